"""``psyop audit``: render every condition of a protocol and check what the participant sees
(per-primitive visible area by mode, hidden primitives that show, identical intervals).
See docs/protocols.md ("Auditing a protocol") and docs/rendering.md."""

from psyop.audit.report import format_table, write_contact_sheet
from psyop.audit.run import AuditReport, AuditSettings, FrameRecord, run_audit

__all__ = ["AuditReport", "AuditSettings", "FrameRecord", "format_table", "run_audit", "write_contact_sheet"]
