"""Every device lives here, behind the small interfaces in hw/base.py."""
