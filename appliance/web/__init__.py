"""The LAN web UI (Flask app factory, served by waitress).

    from appliance.web import create_app
    app = create_app(bench_service, {"data_dir": "/var/lib/inkslice"})

See app.py for the config keys, server.py for serving it with waitress.
"""


def create_app(service, config=None):
    from .app import create_app as _create

    return _create(service, config)
