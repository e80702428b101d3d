"""Run a module under cProfile with a CPU-time clock (``time.process_time``), not wall time: a profile that
stays valid on a loaded machine (a preempted node's wall time is not its cost).  bench_ros.py ``--profile``.

    python bench/cpu_profile.py OUT.prof jident_ros.nodes.windowing --ros-args ...
"""
from __future__ import annotations

import cProfile
import runpy
import sys
import time


def main() -> None:
    out, module, *rest = sys.argv[1:]
    sys.argv = [module, *rest]
    prof = cProfile.Profile(time.process_time)
    try:
        prof.runcall(runpy.run_module, module, run_name="__main__", alter_sys=True)
    except SystemExit:
        pass
    finally:
        prof.dump_stats(out)


if __name__ == "__main__":
    main()
