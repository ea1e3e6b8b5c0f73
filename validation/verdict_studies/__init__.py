"""Studies of the verdict rule, each an ``exposim validate NAME`` (:class:`~validation.protocol.Study`).

On simulated tables, :mod:`~validation.verdict_studies.calibrate` (``verdict-rates``); on a finished
study's folder, without writing into it: :mod:`~validation.verdict_studies.study_power`
(``study-power``), :mod:`~validation.verdict_studies.study_calibration` (``study-calibration``),
:mod:`~validation.verdict_studies.own_residuals` (``own-residuals``) and
:mod:`~validation.verdict_studies.live_checks` (``level-shift``, ``monte-carlo``).  They sit above
the statistics (:mod:`validation.verdicts`) and the studies whose folders they read
(:mod:`validation.live`, :mod:`validation.ae_study`).
"""
