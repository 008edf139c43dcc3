"""The ``uqgear`` command line: one module a group of commands, each adding its parsers and handlers.

It sits at the top of the data path and may import every other subpackage.

::

    uqgear validate STUDY.yaml
    uqgear run STUDY.yaml --out DIR [--scheduler ADDRESS] [--workers N] [--resume] [--quiet]
    uqgear report DIR
    uqgear simulate --speed RPM [--drive-torque NM] [--adhesion-torque NM] [--design NAME|FILE]
                    [--out FILE.png|FILE.nc]
    uqgear synth-rig --design FILE --out FILE.nc [--effect NAME:param=value ...] [--true KEY=VALUE ...] [--seed N]
                     [--ramp START:STOP:RATE[:TORQUE] ...] [--foreign GRADE [--gears-seed N]]
    uqgear calibrate RIG.nc --out DIR [--design FILE] [--params ...]
    uqgear diagnose RIG.nc --out DIR [--design FILE] [--effects ...] [--reference HEALTHY.nc]
    uqgear blindtest --out DIR [--n-per-effect N] [--seed S] [--suite library|real_world|encoderless|runup|foreign]

A user mistake (a study that breaks the schema, a missing file, bad YAML, an
unreachable scheduler, a rig file without usable signal) ends with exit status
2 and a one-line message on standard error, without a traceback, and leaves no
partial output: every command that writes a folder writes into a hidden
sibling folder ``.DIR.partial`` and renames it to ``DIR`` only when everything
is written (:class:`~uqgear.common.transaction.OutputFolder`, which the Python
API's writers use too). Such mistakes are
found before the work starts. An interrupted run (Ctrl-C, a killed job) keeps
that folder, with its chunk checkpoints, so that ``--resume`` continues where
it stopped.

A failure of uqgear's own computation after the input was accepted
(:class:`~uqgear.common.errors.InternalError`) is no mistake of the user's:
it ends with exit status 1 and one line ``uqgear: internal error during
diagnosis step 'STEP': ...`` naming the step that failed, and keeps what was
finished: ``diagnose``, ``calibrate`` and ``blindtest`` publish their folder
with the outputs written so far and ``failure.json`` (the step, the error, its
traceback, the finished steps and what they found); ``run`` keeps its work
folder for ``--resume``.
"""

from .app import build_parser, main
from .base import EXIT_INTERNAL_ERROR, EXIT_INTERRUPTED, EXIT_USER_ERROR

__all__ = ["EXIT_INTERNAL_ERROR", "EXIT_INTERRUPTED", "EXIT_USER_ERROR", "build_parser", "main"]
