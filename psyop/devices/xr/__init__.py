"""OpenXR headset sessions (``--display openxr``, ``--pose openxr``, ``--tracker openxr``,
``--responses openxr``): the runtime connection (runtime), the display that implements the
loop's frame seam (display) and the tracking sources that read the same runtime (tracking).
docs/headset.md says how to run them and what was tested."""
