"""The virtual bench: known surfaces, a camera renderer, the firmware under simavr."""
