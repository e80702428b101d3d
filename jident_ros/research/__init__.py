"""Research code: what reproduces the paper and validates the product, never what runs beside a drive.

The runtime (the nodes; ``jident diagnose``, ``jident trend``, ``jident salvage``) imports nothing from here
(test/test_layers.py checks it).  Here:

* :mod:`~jident_ros.research.evaluation`: the full-grid evaluation (``jident evaluate``, docs/results.md), the
  robustness sweeps, the reports and figures, the validation of the trend and of the verdicts, the zoo report;
* :mod:`~jident_ros.research.second_drive` and :mod:`~jident_ros.research.vector_drive`: independent drive models
  that write recordings to validate the product against (docs/second_drive.md, docs/vector_drive.md);
* :mod:`~jident_ros.research.khm_reference`: the K-harmonic-means estimator the pipeline's batched fit is tested
  against (a reference implementation).
"""
