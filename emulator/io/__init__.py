"""Every file format exposim reads or writes, once, reader and writer side by side.

Nothing outside this package opens a file: numeric modules take and return arrays, and
reporting code saves figures through :func:`emulator.io.files.save_figure`.

=========================  ==========================================================
module                     format
=========================  ==========================================================
:mod:`.files`              atomic writes; metadata JSON (``run.json``, ``exposim.json``,
                           ``scene.json``); ``results.json``; markdown; figures; ``.npz``
:mod:`.png`                16-bit Bayer PNG frames (12-bit DN), 8-bit viewable PNGs
:mod:`.borealhdr`          the BorealHDR recording layout (scan into
                           :mod:`emulator.core.dataset`, frame writer, levels, response lookup)
:mod:`.layout`             where calibration files live: the BorealHDR sample, a clone
                           of the BorealHDR repository, symlinked zips; dated choice
:mod:`.pcalib`             the pcalib inverse-response text format
:mod:`.stack`              TUM monoVO ``times.txt`` and calibration stacks
:mod:`.tum`                TUM pose files (one quaternion convention: xyzw, qw >= 0)
:mod:`.camera_info`        ROS ``camera_info`` YAML
:mod:`.exr`                OpenEXR radiance
:mod:`.export`             one method's run images for SLAM: EuRoC, TUM lists, ROS 2 bag
:mod:`.runfolder`          the run folder of ``exposim run`` (writer with lock and
                           resume, reader, CSV tables)
=========================  ==========================================================

Import the module you need (``from emulator.io.borealhdr import load_sequence``); this
package imports none of them, so ``import emulator.io`` is free.
"""
