"""Assembling and running sessions: the backend registry (:mod:`psyop.run.backends`), the assembly of one
session's backends (:mod:`psyop.run.assembly`), the session lifecycle (:mod:`psyop.run.runner`), simulated
datasets (:mod:`psyop.run.simulate`) and resuming (:mod:`psyop.run.resume`).

It sits above both :mod:`psyop.session` (the loop, plan, log, clock and simulated sources) and
:mod:`psyop.devices` (the adapters that implement the session's seams), so neither of those imports
the other's side: the session never names a device, and a device never names what assembles it
(docs/architecture.md, .importlinter).
"""
