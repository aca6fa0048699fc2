"""inkslice settings: show and change the box's settings, back them up and restore them.

It talks to the running daemon over its socket when there is one (the daemon checks and stores),
and otherwise opens the data folder's store itself; either way the values are parsed the way the
web's JSON carries them (settings.parse_text) and checked by settings.validate, so the CLI, the web
form and the daemon refuse a bad value with the same sentence.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

from .. import datadir
from ..errors import SettingError

NAME = "settings"
ORDER = 65
HELP = "show or change the box's settings (inkslice settings set level_step_mm=0.25), back up and restore"


def add_arguments(p):
    p.add_argument(
        "action",
        choices=("show", "set", "schema", "backup", "restore"),
        help="show: every setting; set KEY=VALUE ...; schema: types, units, ranges, help (JSON); "
        "backup -o FILE: settings and calibration; restore FILE",
    )
    p.add_argument(
        "items", nargs="*", metavar="KEY=VALUE | FILE", help="for set: the changes; for restore: the file"
    )
    p.add_argument("-o", "--out", default=None, help="backup: the file to write (default: stdout)")
    p.add_argument("--data", default=None, help=datadir.HELP)
    p.add_argument("--socket", default=None, help="the daemon's control socket (default DATA/daemon.sock)")


class _Offline:
    """The store itself, for a box whose daemon is not running."""

    def __init__(self, data):
        from ..daemon.store import Store

        self.store = Store(data)

    def settings(self):
        from ..daemon import settings as S

        return S.full(self.store.load_settings())

    def update_settings(self, changes):
        from ..daemon import settings as S

        new = S.validate(self.settings(), changes)
        self.store.save_settings({k: new[k] for k in changes})
        return new

    def backup(self):
        from ..daemon.backup import backup

        return backup(self.store)

    def restore(self, doc):
        from ..daemon.backup import restore

        return restore(self.store, doc)

    def close(self):
        self.store.close()


def _service(args):

    data = datadir.data_dir(args.data)
    sock = Path(args.socket or data / "daemon.sock")
    if sock.exists():
        from ..daemon.rpc import BenchClient

        return BenchClient(sock)
    if not data.is_dir():
        raise SettingError("--data", f"{data} is not a data folder (no daemon socket there either)")
    return _Offline(data)


def parse_changes(items) -> dict:
    from ..daemon import settings as S

    changes = {}
    for item in items:
        key, sep, text = item.partition("=")
        if not sep or not key:
            raise SettingError(item, "want KEY=VALUE")
        changes[key] = S.parse_text(key, text)
    if not changes:
        raise SettingError("settings set", "name at least one KEY=VALUE")
    return changes


def run(args):
    from ..daemon import settings as S

    if args.action == "schema":
        print(json.dumps(S.schema_json(), indent=2))
        return 0
    if args.action == "set":
        changes = parse_changes(args.items)  # before any connection: a typo needs no daemon
    if args.action == "restore":
        if len(args.items) != 1:
            raise SettingError("settings restore", "name one backup file")
        try:
            doc = json.loads(Path(args.items[0]).read_text(encoding="utf-8"))
        except (OSError, ValueError) as e:
            raise SettingError(args.items[0], f"cannot read the backup: {e}") from None
    service = _service(args)
    try:
        if args.action == "show":
            _show(service.settings())
        elif args.action == "set":
            new = service.update_settings(changes)
            for key in changes:
                print(f"{key} = {json.dumps(new[key])}")
        elif args.action == "backup":
            text = json.dumps(service.backup(), indent=2) + "\n"
            if args.out:
                from .. import atomicio

                atomicio.check_output_file(args.out, "-o")
                atomicio.write_text(args.out, text)
                print(f"{args.out}: settings and calibration backed up")
            else:
                sys.stdout.write(text)
        elif args.action == "restore":
            out = service.restore(doc)
            print(f"restored {out['settings']} settings and {out['calibration']} calibration records")
    finally:
        service.close()
    return 0


def _show(settings):
    from ..daemon import settings as S

    for gid, title in S.GROUPS:
        rows = [s for s in S.SCHEMA if s.group == gid]
        if not rows:
            continue
        print(f"# {title}")
        for s in rows:
            value = "(set)" if s.secret and settings.get(s.key) else json.dumps(settings.get(s.key))
            print(f"{s.key} = {value}" + (f"  [{s.unit}]" if s.unit else ""))
