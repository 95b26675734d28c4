"""Response sources: simulated observers and ``none`` (the keyboard and the serial response box are
in :mod:`psyop.devices.responses`).

Every source turns one trial (its schedule row) into a :class:`Response`.
"""

from psyop.session.responses.base import Response, ResponseKindSpec, ResponseSource

__all__ = ["Response", "ResponseKindSpec", "ResponseSource"]
