"""Response sources: keyboard, serial response box, simulated observers.

Every source turns one trial (its schedule row) into a :class:`Response`.
"""

from psyop.session.responses.base import Response, ResponseKind, ResponseSource, response_kind

__all__ = ["Response", "ResponseKind", "ResponseSource", "response_kind"]
