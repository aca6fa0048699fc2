"""CAM room: height map -> cutter-compensated toolpaths -> G-code; verification. Pure."""
