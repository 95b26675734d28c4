"""The frames an image observer is shown: each interval of a trial drawn by the session's own scene renderer
(psyop.session.scene_renderer.SceneRenderer: the same scene builder, eye rig, rendering mode, anti-aliasing
and linear colour the participant's display gets), at a reduced resolution ``scale``, at evenly spaced times
through the interval, with the eye fixating where the loop's fixation plan asks (psyop.session.loop.fixation_plan:
the pursuit target's path, the static target, the centre), at the fixation target's own depth. In free viewing
(no fixation target) each frame is seen from a fixation of its own (:func:`free_fixations`): a point drawn
uniformly over the disc of the plan's free-viewing radius around its centre, from the plan's per-trial seed,
so successive frames are separated by the saccades a freely looking participant makes.

Not modelled in these frames: the simulated tracker's error and latency (the frames are drawn for the gaze
the eye holds, as a perfect tracker would report it) and frames the display drops."""

from __future__ import annotations

import math
from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np

from psyop.optics.angles import offset_direction
from psyop.protocol.scene import FixationTarget
from psyop.rendering import RenderSettings
from psyop.schedule import interval_values
from psyop.session.gaze.plan import FixationPlan
from psyop.session.loop import LoopFacts, fixation_plan
from psyop.session.phases import PhaseSpec
from psyop.session.plan import SessionPlan
from psyop.session.rows import TrialRow
from psyop.session.scene_renderer import SceneRenderer
from psyop.stimulus import scene_origin_m


@dataclass(frozen=True)
class IntervalFrames:
    """One interval's frames: ``images`` (T, H, W, 3) linear colour, top row first; ``gaze`` (T, 3) the unit
    head-space gaze direction from the eye's centre of rotation at each frame; ``pixel_to_ray`` the camera's
    pixel -> direction matrix (psyop.optics.camera.EyeCamera) of the first frame."""

    images: np.ndarray
    gaze: np.ndarray
    pixel_to_ray: np.ndarray


#: samples per axis of an edge pixel: at the default scale (0.25) a sample every 2.3 arcmin on the Vive Pro,
#: finer than the display's own 4.58 arcmin pixels
EDGE_SAMPLES = 8


def free_fixations(plan: FixationPlan, n: int) -> np.ndarray:
    """(n, 3) unit gaze directions of a free-viewing plan's frames: points uniform over the disc of
    ``plan.radius_deg`` around ``plan.centre_deg`` (radius sqrt(u) R, polar angle uniform), from ``plan.seed``."""
    rng = np.random.default_rng(plan.seed)
    radius_deg = plan.radius_deg * np.sqrt(rng.uniform(size=n))
    angle_deg = rng.uniform(0.0, 360.0, size=n)
    return np.asarray(offset_direction(*plan.centre_deg, radius_deg, angle_deg), dtype=np.float64)


class FrameSource:
    """Renders a trial's intervals for the plan's viewing eye (the right eye of a stereo plan)."""

    def __init__(self, plan: SessionPlan, *, scale: float, frames_per_interval: int) -> None:
        self.plan = plan
        # interval frames only (no text, no cross), each interval's first image checked (finite, not blank);
        # drawn as the participant's display draws them (adaptive anti-aliasing: edges supersampled, psyop.rendering)
        self.renderer = SceneRenderer(plan, scale=scale, max_images=2**62, check_every=2**62)
        self.renderer.settings = RenderSettings(samples_per_axis=EDGE_SAMPLES)
        self.facts = LoopFacts.of_plan(plan)
        self.frames_per_interval = int(frames_per_interval)
        self.eye = "right" if "right" in plan.rig.eyes else plan.rig.eyes[0]

    def interval_phases(self) -> list[PhaseSpec]:
        """The plan's stimulus phases (one per interval), in order."""
        return [phase for phase in self.plan.phases if phase.show == "stimulus"]

    def intervals(self, row: TrialRow) -> Iterator[IntervalFrames]:
        """Each interval of trial ``row``, in order."""
        for phase in self.interval_phases():
            yield self.interval(row, phase)

    def interval(self, row: TrialRow, phase: PhaseSpec) -> IntervalFrames:
        """The frames of ``phase`` in trial ``row``."""
        mode = self.plan.mode_for(phase, dict(row))
        centre = np.asarray(self.plan.rig.centre_m(self.eye), dtype=np.float64)
        origin = scene_origin_m(self.plan.protocol, centre)
        target = fixation_plan(self.facts, phase, row, 0.0)
        distance_m = self._fixation_distance_m(row, phase, target.distance_m)
        images, gazes = [], []
        ray = np.eye(3)
        free = free_fixations(target, self.frames_per_interval) if target.kind == "free" else None
        for k in range(self.frames_per_interval):
            t_s = (k + 0.5) * phase.duration_s / self.frames_per_interval
            direction = free[k] if free is not None else np.asarray(target.target_direction(t_s), dtype=np.float64)
            fixation = origin + direction * distance_m
            point = (float(fixation[0]), float(fixation[1]), float(fixation[2]))
            self.renderer.render(row, phase, mode, t_s, point)
            image = self.renderer.linear_image(self.eye)
            if image is None:  # nothing drawn in this interval
                raise ValueError(f"interval {phase.interval} draws nothing for the image observer to see")
            images.append(image)
            gaze = fixation - centre
            gazes.append(gaze / np.linalg.norm(gaze))
            if k == 0:
                ray = self.plan.rig.camera(self.renderer.display, self.eye, point, mode, row=row).pixel_to_ray
        return IntervalFrames(np.stack(images), np.stack(gazes), np.asarray(ray))

    def _fixation_distance_m(self, row: TrialRow, phase: PhaseSpec, default_m: float) -> float:
        """The distance of what the eye fixates: the fixation target's depth in this interval, else the plan's."""
        values = interval_values(row, max(1, phase.interval))
        for item in self.plan.protocol.scene:
            if isinstance(item, FixationTarget):
                depth_D = float(item.depth.resolve_D(values))
                return default_m if not math.isfinite(depth_D) or depth_D <= 0 else 1.0 / depth_D
        return default_m

    def close(self) -> None:
        self.renderer.close()
