"""Names for the untyped records psyop passes across its seams: the one definition of each alias.

JSON documents (session.json as written, BIDS sidecars, dataset_description.json) and trial rows are read
and written as mappings from column or key names to values. Their values are deliberately
``Any`` here, in one place, each with its reason: a reader checks the keys it uses where it reads
them (session.json is read as the typed ``psyop.session.log.record.SessionRecord``). Replacing an alias
by a TypedDict or a pydantic model tightens every annotation that uses it at once (docs/architecture.md,
"Types and lint"). psyop.session.rows re-exports these names.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

JsonObject = dict[str, Any]  # Any: a JSON object's values (str, number, bool, None, list, object)
JsonMapping = Mapping[str, Any]  # Any: the same, read-only
TrialRow = Mapping[str, Any]  # Any: a trial row's cells (factor levels: float, str, bool, None)
#: one trial's record as the loop fills it (the schedule row plus response, timing and gaze columns)
TrialRecord = dict[str, Any]  # Any: as TrialRow
Loc = tuple[str | int, ...]  # where in a document: keys and list indices, outermost first (pydantic's loc)
