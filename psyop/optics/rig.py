"""The eye rig: which eye(s) see the stimulus, the eye model (NC) and the ipd, together.

It is the one place that says where each eye's centre of rotation C is in head space
(``(-ipd/2, 0, 0)`` left, ``(+ipd/2, 0, 0)`` right; docs/architecture.md) and that builds an
eye's camera for a fixation and a rendering mode. The session plan (psyop.session.plan) holds
one; the renderers take their eye centres and cameras from it.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from psyop.optics.camera import EyeCamera, ViewGeometry, make_eye_camera, make_view_camera
from psyop.optics.display import DisplayProfile
from psyop.optics.eye_models import EyeModel
from psyop.optics.nodal import eye_centre_m
from psyop.optics.ranges import IPD_M, NC_M
from psyop.records import TrialRow


EYE_NAMES: tuple[str, ...] = ("left", "right")


@dataclass(frozen=True)
class NcRule:
    """The NC the renderer uses instead of the eye model's (a protocol's ``display.rendering_nc``):
    ``nc_m`` fixed, ``scale`` times the eye model's, or the trial row's ``column`` (in mm when
    ``column_unit`` is ``mm``, a multiple of the eye model's NC when it is ``scale``).

    Examples
    --------
    >>> NcRule(column="nc_mm", column_unit="mm").nc_m_for(0.0077, {"nc_mm": 10.0})
    0.01
    >>> NcRule(scale=2.0).nc_m_for(0.005, None)
    0.01
    >>> rule = NcRule(column="nc_mm", column_unit="mm", signed=True)
    >>> rule.nc_m_for(0.0077, {"nc_mm": -4.0}), rule.signed_nc_m_for(0.0077, {"nc_mm": -4.0})
    (0.004, -0.004)

    ``signed``: the column's sign is the trial's mode (> 0 ocular, 0 conventional, < 0 reversed, set by the
    schedule) and its size the NC; at 0 no NC is rendered (conventional) and the eye model's is returned.
    """

    nc_m: float | None = None
    scale: float | None = None
    column: str | None = None
    column_unit: str = "mm"
    signed: bool = False

    def signed_nc_m_for(self, eye_model_nc_m: float, row: TrialRow | None) -> float:
        """The signed NC of a ``signed`` rule's trial (its level in metres); for other rules :meth:`nc_m_for`."""
        if not self.signed:
            return self.nc_m_for(eye_model_nc_m, row)
        level = self._level(row)
        value = level / 1000.0 if self.column_unit == "mm" else level * eye_model_nc_m
        return 0.0 if value == 0.0 else float(math.copysign(NC_M.check(abs(value), "the rendered NC"), value))

    def _level(self, row: TrialRow | None) -> float:
        if row is None or self.column is None or self.column not in row:
            raise ValueError(f"the rendered NC is the trial's {self.column!r}; this frame has no trial row")
        return float(row[self.column])

    def nc_m_for(self, eye_model_nc_m: float, row: TrialRow | None) -> float:
        if self.nc_m is not None:
            value = self.nc_m
        elif self.scale is not None:
            value = self.scale * eye_model_nc_m
        else:
            level = self._level(row)
            value = level / 1000.0 if self.column_unit == "mm" else level * eye_model_nc_m
            if self.signed:  # the sign is the mode (reversed below 0); at 0 the camera is conventional
                value = abs(value) if value != 0.0 else eye_model_nc_m
        return NC_M.check(value, "the rendered NC")

    def as_dict(self) -> dict[str, object]:
        return {"nc_m": self.nc_m, "scale": self.scale, "column": self.column, "column_unit": self.column_unit,
                "signed": self.signed}


@dataclass(frozen=True)
class EyeRig:
    """``eyes``: the eyes that see the stimulus (``("right",)``, ``("left",)`` or both, stereo).
    ``ipd_source``: where ``ipd_m`` came from (``protocol``, ``tracker`` or ``default``)."""

    eye_model: EyeModel
    ipd_m: float
    eyes: tuple[str, ...] = ("right",)
    ipd_source: str = "protocol"
    rendering_nc: NcRule | None = None  # None: render with the eye model's NC

    def __post_init__(self) -> None:
        IPD_M.check(self.ipd_m)
        NC_M.check(self.eye_model.nc_m, f"NC of eye model {self.eye_model.name!r}")
        if not self.eyes or any(e not in EYE_NAMES for e in self.eyes) or len(set(self.eyes)) != len(self.eyes):
            raise ValueError(f"eyes must be left and/or right, got {self.eyes!r}")

    @classmethod
    def for_protocol_eyes(cls, eyes: str, eye_model: EyeModel, ipd_m: float, ipd_source: str,
                          rendering_nc: NcRule | None = None) -> "EyeRig":
        """``eyes``: the protocol's ``eyes:`` value (``right``, ``left`` or ``stereo``)."""
        return cls(eye_model, float(ipd_m), EYE_NAMES if eyes == "stereo" else (eyes,), ipd_source, rendering_nc)

    def rendered_nc_m(self, row: TrialRow | None = None) -> float:
        """The NC this trial is rendered with: the eye model's, or the protocol's ``rendering_nc``."""
        if self.rendering_nc is None:
            return self.nc_m
        return self.rendering_nc.nc_m_for(self.nc_m, row)

    @property
    def nc_m(self) -> float:
        return self.eye_model.nc_m

    @property
    def stereo(self) -> bool:
        return len(self.eyes) == 2

    def centre_m(self, eye: str) -> np.ndarray:
        """This eye's centre of rotation C in head space, metres."""
        if eye not in EYE_NAMES:
            raise ValueError(f"eye must be left or right, got {eye!r}")
        return eye_centre_m(eye, self.ipd_m)

    def camera(self, display: DisplayProfile, eye: str, fixation_m: ArrayLike, mode: str,
               row: TrialRow | None = None, **kwargs: float) -> EyeCamera:
        """The camera of ``eye`` for this frame (``psyop.optics.camera.make_eye_camera``); ``row``: the
        trial's row, for a rendered NC that is a factor (:class:`NcRule`)."""
        return make_eye_camera(display, eye, fixation_m, self.ipd_m, self.rendered_nc_m(row), mode, **kwargs)

    def view_camera(self, view: ViewGeometry, width_px: int, height_px: int, fixation_m: ArrayLike,
                    mode: str, row: TrialRow | None = None, **kwargs: float) -> EyeCamera:
        """The camera of a view a headset runtime reported (``psyop.optics.camera.make_view_camera``),
        with this rig's rendered NC (``row``: the trial's row, as :meth:`camera`). Place the views with
        :meth:`place_views` first."""
        return make_view_camera(view, width_px, height_px, fixation_m, self.rendered_nc_m(row), mode, **kwargs)

    def place_views(self, views: tuple[ViewGeometry, ...]) -> tuple[ViewGeometry, ...]:
        """The runtime's views with each eye's centre of rotation C where this rig says it is.

        The runtime's view position of an eye is taken to be that eye's centre of rotation C
        (docs/headset.md). With the ipd from the tracker (``ipd: tracker``, ``ipd_source``
        'runtime') the views are used as reported. With an ipd the protocol fixes, the two
        centres are moved symmetrically along the line joining the runtime's two view
        positions, about their mid-point, to ``ipd_m`` apart (orientations and fields of view
        unchanged); a single view is then left where the runtime put it."""
        if self.ipd_source != "protocol" or len(views) != 2:
            return views
        by_eye = {v.eye: v for v in views}
        if set(by_eye) != set(EYE_NAMES):
            return views
        left, right = (np.asarray(by_eye[e].centre_m, dtype=np.float64) for e in EYE_NAMES)
        mid, axis = 0.5 * (left + right), right - left
        norm = float(np.linalg.norm(axis))
        if not norm > 0.0:
            raise ValueError("the runtime reported both eyes at the same position; cannot place a fixed ipd")
        half = 0.5 * self.ipd_m * axis / norm
        placed = {"left": mid - half, "right": mid + half}
        return tuple(dataclasses.replace(v, centre_m=_xyz(placed[v.eye])) for v in views)

    def as_dict(self) -> dict[str, object]:
        """What session.json records."""
        return {"eyes": list(self.eyes), "ipd_m": self.ipd_m, "ipd_source": self.ipd_source,
                "eye_model": self.eye_model.name, "nc_m": self.nc_m,
                "rendering_nc": None if self.rendering_nc is None else self.rendering_nc.as_dict()}


def _xyz(point_m: np.ndarray) -> tuple[float, float, float]:
    """A 3-vector as a tuple of three floats (a ViewGeometry centre)."""
    x, y, z = (float(v) for v in point_m)
    return (x, y, z)
