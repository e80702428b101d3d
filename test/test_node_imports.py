"""The nodes' import closure (issue 25): no node loads ``scipy.signal``, ``scipy.stats`` or ``scipy.optimize``.

Those three cost about 44 MiB of the diagnostic node's resident memory (163-168 MiB peak with them, target
<= 150 MiB) and a second of its start-up; the runtime needs only ``scipy.special``, ``fft``, ``linalg`` and
``ndimage`` (stream/filters.py, identify/distributions.py; ``scipy.optimize`` is imported where the trend designs its
CUSUM threshold, once per configuration).  A module that imports one of
them again at its top fails here, by name.
"""
from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
HEAVY = ("scipy.signal", "scipy.stats", "scipy.optimize", "scipy.interpolate", "scipy.spatial")
NODES = ("diagnostic", "windowing", "replay", "simulator")


def test_nodes_load_no_heavy_scipy_module():
    code = textwrap.dedent(f"""
        import json, sys
        for node in {NODES!r}:
            __import__("jident_ros.nodes." + node)
        import jident_ros.cli.offline
        print(json.dumps(sorted(m for m in sys.modules if m.startswith({HEAVY!r}))))
    """)
    env = dict(os.environ, PYTHONPATH=str(REPO))
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300, env=env,
                       cwd=str(REPO))
    assert r.returncode == 0, r.stderr[-3000:]
    loaded = json.loads(r.stdout.strip().splitlines()[-1])
    assert loaded == [], f"a node imports {loaded[:5]}: find the importer with `python -X importtime`"
