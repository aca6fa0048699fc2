"""python -m appliance.sim.processing_child SCAN OUT OPTIONS_JSON: the daemon's
processing child (daemon/processing_child.py) with the ground truth of a scan of
a known part, so the simulated bench's reports carry statistics."""

import sys

from ..daemon.processing_child import main
from .truth import find_truth

if __name__ == "__main__":
    sys.exit(main(sys.argv[1:], truth_for=find_truth))
