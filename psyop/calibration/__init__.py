"""Display calibration (``psyop calibrate``, docs/calibration.md): the patch sequence, the transfer-function
model fitted to photometer readings, and the calibration file.

- :mod:`psyop.calibration.model`: gain-offset-gamma per channel (``L(v) = a + k * max(0, (1 - o) v + o) ** gamma``),
  a monotone cubic (PCHIP) through the level means, chosen by leave-one-level-out error; the readings' checks
  (non-monotone, noisy), each a one-line :class:`~psyop.errors.UserError`;
- :mod:`psyop.calibration.record`: the calibration file (JSON, written with :func:`psyop.atomic.write_atomic`), its
  partial form after a fault, and reading it back;
- :mod:`psyop.calibration.patches`: the full-field patches, on a headless EGL framebuffer (with a patch log a
  photometer emulator can read) or in a glfw window on the display being calibrated;
- :mod:`psyop.calibration.measure`: the run: each patch shown, then read, a fault kept as a partial file.

The layer sits with psyop.stimulus and psyop.adaptive: it imports psyop.rendering (the GL context of the patches),
psyop.atomic and psyop.errors, never psyop.devices (the photometer adapters, psyop.devices.photometers, meet it
through the structural :class:`~psyop.calibration.measure.Photometer` protocol; psyop.cli.calibrate wires both).
"""
