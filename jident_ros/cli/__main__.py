"""python -m jident_ros.cli"""
import sys

from jident_ros.cli.main import main

sys.exit(main())
