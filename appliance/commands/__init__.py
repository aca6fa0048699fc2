"""One module per `inkslice` sub-command (see appliance/cli.py)."""
