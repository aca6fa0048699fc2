"""The admin's own account under /api/: the password, and the API tokens scripts log in with.

A new password or token is made only from a logged-in browser session: a token cannot make
more tokens or change the password. Behind the login gate (app.py).
"""

from __future__ import annotations

import re

from flask import Blueprint, g, jsonify, session

from . import auth
from .apicore import Refused, err, ext, json_body, json_errors

bp = json_errors(Blueprint("account", __name__))


@bp.post("/password")
def change_password():
    if g.auth != "session":
        return err("change the password from a logged-in browser session", 403)
    body = json_body()
    creds = ext()["creds"]
    ok, wait = auth.checked_password(
        ext()["limiter"], creds, "password:" + auth.client_address(), body.get("current", "")
    )
    if ok is None:
        resp = jsonify(error=f"too many wrong passwords; try again in {int(wait) + 1} s", where="current")
        return resp, 429, {"Retry-After": str(int(wait) + 1)}
    if not ok:
        return err("the current password is wrong", 403, "current")
    try:
        gen = creds.set_password(body.get("new", ""))
    except ValueError as e:
        return err(str(e), 400, "new")
    session["gen"] = gen  # this session stays in; every other one is logged out
    ext()["sessions"].revoke_all(keep=session.get("sid"))
    auth.first_login_done(ext()["config"])
    return jsonify(ok=True)


@bp.get("/tokens")
def list_tokens():
    return jsonify(tokens=ext()["creds"].list_tokens())


@bp.post("/tokens")
def create_token():
    if g.auth != "session":
        return err("tokens are made from a logged-in browser session", 403)
    rec, token = ext()["creds"].create_token(json_body().get("name", ""))
    return jsonify(token=token, **rec), 201


@bp.delete("/tokens/<token_id>")
def revoke_token(token_id):
    if not re.match(r"^[0-9a-f]{8}$", token_id):
        raise Refused("bad token id", 400)
    if not ext()["creds"].revoke_token(token_id):
        return err("no such token", 404)
    return jsonify(ok=True)
