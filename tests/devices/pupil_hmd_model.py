"""The eyes a Pupil Capture stand-in watches, and the HMD 3-D calibration it fits from reference data.

What Capture's HMD 3D calibration does (pupil_src/shared_modules/calibration_choreography/hmd_plugin.py,
gaze_mapping/gazer_3d/gazer_hmd.py): it collects pupil data while calibrating, appends every
``calibration.add_ref_data`` ``ref_data`` entry (``mm_pos``, ``timestamp``) to its reference list, matches each
reference point to the pupil data closest in time, and fits each eye camera's pose in the frame of the reference
points, the eyes' centres being the ``translation_eye0`` / ``translation_eye1`` it was started with; its gaze
afterwards is in that frame (mm). Capture fits by bundle adjustment; here each eye camera's rotation is fitted by
least squares (scipy's ``Rotation.align_vectors``: the pupil normals against the directions from the eye's centre
to each reference point), and the fit fails when too few points matched in time or the mean angular residual
exceeds ``max_residual_deg``: a reference frame that is mirrored, a position in metres, or a timestamp not in
Pupil time cannot fit. (A frame that is only rotated fits, as in Capture; then the gaze mapped afterwards comes out
in that rotated frame, which the tests check.)

The participant's eyes: centres ``+-separation_m / 2`` on the head's x axis (eye 0 the right eye), each watched
by an eye camera at a fixed rotation the client never learns; the pupil normal of an eye looking at a point is the
unit vector from its centre to the point, in its camera's frame. Head space is psyop's: x right, y up, -z forward.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass, field

import numpy as np
from scipy.spatial.transform import Rotation

#: each eye camera's orientation (head space -> camera frame): eye 0 (right) and eye 1 (left), looking up at the eye
CAMERA_ROTATIONS = (Rotation.from_euler("xyz", [25.0, -15.0, 160.0], degrees=True),
                    Rotation.from_euler("xyz", [25.0, 15.0, -160.0], degrees=True))


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


@dataclass
class Eyes:
    """The participant's eyes: where they look (head space, m; None: straight ahead at 1 m); ``next_look``: where
    they will look from a Pupil time on (a saccade after a target appears: set it with :meth:`look_from`)."""

    separation_m: float = 0.064
    look_at_head_m: tuple[float, float, float] | None = None
    next_look: tuple[float, tuple[float, float, float]] | None = None

    def look_from(self, pupil_t: float, point_m: tuple[float, float, float]) -> None:
        self.next_look = (pupil_t, point_m)

    def at(self, pupil_t: float) -> None:
        """Move the gaze when ``pupil_t`` reached the next look's time."""
        if self.next_look is not None and pupil_t >= self.next_look[0]:
            self.look_at_head_m, self.next_look = self.next_look[1], None

    def centres_m(self) -> tuple[np.ndarray, np.ndarray]:
        """(eye 0 = right, eye 1 = left) centres in head space."""
        half = 0.5 * self.separation_m
        return np.array([half, 0.0, 0.0]), np.array([-half, 0.0, 0.0])

    def pupil_normals(self) -> tuple[np.ndarray, np.ndarray]:
        """Each eye's pupil normal in its own camera's frame."""
        target = np.array(self.look_at_head_m if self.look_at_head_m is not None else (0.0, 0.0, -1.0))
        return tuple(CAMERA_ROTATIONS[i].apply(_unit(target - c))  # type: ignore[return-value]
                     for i, c in enumerate(self.centres_m()))


@dataclass
class HmdFit:
    """A fitted HMD 3-D mapping: each eye camera's rotation into the reference frame and the eye centres there
    (mm, as Capture was given them)."""

    rotations: tuple[Rotation, Rotation]
    translations_mm: tuple[np.ndarray, np.ndarray]
    residual_deg: tuple[float, float]
    n_matched: int

    def gaze(self, normals: tuple[np.ndarray, np.ndarray]) -> dict:
        """A binocular gaze datum's 3-D fields (reference frame, mm), as Capture's binocular 3-D gazer maps them:
        each eye's gaze normal, and the point nearest both gaze rays."""
        g = [self.rotations[i].inv().apply(normals[i]) for i in range(2)]
        c = self.translations_mm
        # closest points of the rays c0 + s g0 and c1 + u g1
        w = c[0] - c[1]
        a, b, cc, d, e = g[0] @ g[0], g[0] @ g[1], g[1] @ g[1], g[0] @ w, g[1] @ w
        denom = a * cc - b * b
        s, u = ((b * e - cc * d) / denom, (a * e - b * d) / denom) if abs(denom) > 1e-12 else (1000.0, 1000.0)
        point = 0.5 * ((c[0] + s * g[0]) + (c[1] + u * g[1]))
        return {"gaze_point_3d": point.tolist(), "eye_centers_3d": {0: c[0].tolist(), 1: c[1].tolist()},
                "gaze_normals_3d": {0: g[0].tolist(), 1: g[1].tolist()}}

    def params(self) -> dict:
        """``calibration.result.v2`` ``params`` in Capture's shape (binocular model: eye camera -> world)."""
        matrices = {}
        for i in range(2):
            m = np.eye(4)
            m[:3, :3] = self.rotations[i].inv().as_matrix()
            m[:3, 3] = self.translations_mm[i]
            matrices[f"eye_camera_to_world_matrix{i}"] = m.tolist()
        return {"left_model": {}, "right_model": {}, "binocular_model": matrices}


@dataclass
class HmdCalibration:
    """One HMD 3-D calibration in progress: the eye translations it was started with, the pupil data and the
    reference data it collected."""

    translations_mm: tuple[np.ndarray, np.ndarray]
    pupil: list[tuple[float, np.ndarray, np.ndarray]] = field(default_factory=list)  # (pupil time, n0, n1)
    refs: list[dict] = field(default_factory=list)

    def fit(self, rate_hz: float, max_residual_deg: float = 1.0, min_matches: int = 20) -> HmdFit | str:
        """The fit, or why it failed (Capture >= 2.0 says ``CalibrationError`` for both; the text is for tests)."""
        if not self.pupil or not self.refs:
            return "not enough data: no pupil or no reference data"
        times = np.array([p[0] for p in self.pupil])
        matched: list[tuple[np.ndarray, np.ndarray, np.ndarray]] = []
        for ref in self.refs:
            k = int(np.argmin(np.abs(times - float(ref["timestamp"]))))
            if abs(times[k] - float(ref["timestamp"])) <= 1.0 / rate_hz:
                matched.append((np.asarray(ref["mm_pos"], dtype=np.float64), self.pupil[k][1], self.pupil[k][2]))
        if len(matched) < min_matches:
            return f"not enough data: {len(matched)} reference points matched pupil data in time"
        rotations, residuals = [], []
        for i in range(2):
            directions = _unit(np.array([m[0] for m in matched]) - self.translations_mm[i])
            normals = np.array([m[1 + i] for m in matched])
            with warnings.catch_warnings():  # degenerate data (the eyes never moved) warns; the residual says it
                warnings.simplefilter("ignore", UserWarning)
                rotation, _ = Rotation.align_vectors(normals, directions)
            predicted = rotation.apply(directions)
            cos = np.clip(np.sum(predicted * normals, axis=1), -1.0, 1.0)
            rotations.append(rotation)
            residuals.append(float(np.degrees(np.mean(np.arccos(cos)))))
        if not all(math.isfinite(r) and r <= max_residual_deg for r in residuals):
            return f"fit did not converge: mean residuals {residuals[0]:.2f} and {residuals[1]:.2f} deg"
        return HmdFit((rotations[0], rotations[1]), self.translations_mm, (residuals[0], residuals[1]), len(matched))
