"""The scan runner: state machine, job store, recovery."""
