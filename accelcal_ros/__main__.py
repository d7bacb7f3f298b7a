"""``python -m accelcal_ros`` runs the offline command line (same as ``accelcal``)."""
import sys

from accelcal_ros.cli import main

sys.exit(main())
