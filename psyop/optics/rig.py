"""The eye rig: which eye(s) see the stimulus, the eye model (NC) and the ipd, together.

It is the one place that says where each eye's centre of rotation C is in head space
(``(-ipd/2, 0, 0)`` left, ``(+ipd/2, 0, 0)`` right; docs/architecture.md) and that builds an
eye's camera for a fixation and a rendering mode. The session plan (psyop.session.plan) holds
one; the renderers take their eye centres and cameras from it.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from psyop.optics.camera import EyeCamera, ViewGeometry, make_eye_camera, make_view_camera
from psyop.optics.display import DisplayProfile
from psyop.optics.eye_models import EyeModel
from psyop.optics.ranges import IPD_M, NC_M

EYE_NAMES: tuple[str, ...] = ("left", "right")


@dataclass(frozen=True)
class EyeRig:
    """``eyes``: the eyes that see the stimulus (``("right",)``, ``("left",)`` or both, stereo).
    ``ipd_source``: where ``ipd_m`` came from (``protocol``, ``tracker`` or ``default``)."""

    eye_model: EyeModel
    ipd_m: float
    eyes: tuple[str, ...] = ("right",)
    ipd_source: str = "protocol"

    def __post_init__(self) -> None:
        IPD_M.check(self.ipd_m)
        NC_M.check(self.eye_model.nc_m, f"NC of eye model {self.eye_model.name!r}")
        if not self.eyes or any(e not in EYE_NAMES for e in self.eyes) or len(set(self.eyes)) != len(self.eyes):
            raise ValueError(f"eyes must be left and/or right, got {self.eyes!r}")

    @classmethod
    def for_protocol_eyes(cls, eyes: str, eye_model: EyeModel, ipd_m: float, ipd_source: str) -> "EyeRig":
        """``eyes``: the protocol's ``eyes:`` value (``right``, ``left`` or ``stereo``)."""
        return cls(eye_model, float(ipd_m), EYE_NAMES if eyes == "stereo" else (eyes,), ipd_source)

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
        return np.array([(-0.5 if eye == "left" else 0.5) * self.ipd_m, 0.0, 0.0])

    def camera(self, display: DisplayProfile, eye: str, fixation_m: ArrayLike, mode: str,
               **kwargs: float) -> EyeCamera:
        """The camera of ``eye`` for this frame (``psyop.optics.camera.make_eye_camera``)."""
        return make_eye_camera(display, eye, fixation_m, self.ipd_m, self.nc_m, mode, **kwargs)

    def view_camera(self, view: ViewGeometry, width_px: int, height_px: int, fixation_m: ArrayLike,
                    mode: str, **kwargs: float) -> EyeCamera:
        """The camera of a view a headset runtime reported (``psyop.optics.camera.make_view_camera``),
        with this rig's NC. Place the views with :meth:`place_views` first."""
        return make_view_camera(view, width_px, height_px, fixation_m, self.nc_m, mode, **kwargs)

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
        return tuple(dataclasses.replace(v, centre_m=tuple(float(x) for x in placed[v.eye])) for v in views)

    def as_dict(self) -> dict[str, object]:
        """What session.json records."""
        return {"eyes": list(self.eyes), "ipd_m": self.ipd_m, "ipd_source": self.ipd_source,
                "eye_model": self.eye_model.name, "nc_m": self.nc_m}
