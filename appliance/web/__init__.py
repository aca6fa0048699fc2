"""The LAN web UI (Flask app factory, served by waitress)."""
