"""Research code: what reproduces the paper and validates the product, never what runs beside a drive.

The runtime (the nodes; ``jident diagnose``, ``jident trend``, ``jident salvage``) imports nothing from here
(test/test_layers.py checks it).  Here:

* :mod:`~jident_ros.research.khm_reference`: the K-harmonic-means estimator the pipeline's batched fit is tested
  against (a reference implementation).
"""
