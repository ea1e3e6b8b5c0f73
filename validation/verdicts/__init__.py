"""Verdicts with evidence (issue 22): live versus emulated agreement per metric, the AE study's
findings tested as stated (intersection-union tests, Holm), the simulated tables they are calibrated on,
and the power functions that size the studies.

Modules: :mod:`~validation.verdicts.agreement` (the verdict per metric),
:mod:`~validation.verdicts.interaction` (omega2 and its one-sided bootstrap bounds),
:mod:`~validation.verdicts.findings` (the AE study's findings as statistics),
:mod:`~validation.verdicts.simulate` (synthetic metric tables with known truth),
:mod:`~validation.verdicts.power` (verdict rates, smallest detectable interaction, walks needed).
The numeric primitives (bootstrap plans, intervals, Holm, TOST, variance components) are
:mod:`emulator.core.stats`.
"""

#: Realistic scales of the calibration (metric units, method SD 1): the noise of one run
#: over the SD of the method effects, from the live study's control (Kendall tau of two
#: live runs over 4 walks, 60 cycles, 256x160: 0.68 on median matches and uniformity, 0.24
#: on RPE, which a 7-method simulation maps to noise / method SD of 1.0 and 2.8).
NOISE_TO_METHOD_SD = {"matches": 1.0, "rpe": 2.8}
#: The live study's size: walks at which a perfect emulator is judged ``agrees`` in >= 80 %
#: of simulated studies at the matches scale (measured: 40 walks 76 %, 50 walks 89 %, 60 walks 96 %).
STUDY_WALKS = 50
