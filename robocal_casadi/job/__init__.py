"""The jobs a user runs on top of the engine and the report.

``run``: the whole calibration job (calibrate, choose what is delivered, write the files
and the report), the one ``robocal calibrate``, ``robocal demo`` and a fleet's robot task
call; ``choice`` (the delivered geometry-only model, or doing nothing), ``accuracy`` (the
predicted tool-position error over the work cell) and ``projection`` (the geometry nearest
a model with effects) are its steps; the parameters a controller accepts (``--profile``)
come from its format in ``formats``.
``compensation``: joint targets that make a calibrated robot reach nominal poses.

Nothing below this package imports it; its modules are imported from where they are.
"""
