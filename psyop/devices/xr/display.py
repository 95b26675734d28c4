"""``--display openxr``: the loop's :class:`~psyop.session.frames.Display` on an OpenXR headset.

Per frame: ``begin_frame`` drains the runtime's events (a session that is no longer focused
interrupts the trial in progress: :class:`~psyop.session.frames.DisplayInterrupted`), waits in
``xrWaitFrame`` (the runtime paces the loop), begins the frame, syncs input, locates the head
(VIEW space in the reference space) and each eye's view (``xrLocateViews`` in the VIEW space:
head-relative centre, orientation and field of view), and acquires each eye's swapchain image as
the render target. ``end_frame`` releases the images and submits one projection layer in the
reference space with the views the runtime gave for that display time.

Eye positions: the runtime's view position of an eye is taken to be that eye's centre of rotation
C (what the runtime's IPD setting places); the eye rig's ipd rule (``place_views``) then applies
the protocol's fixed ipd, if it has one, about their mid-point. Swapchains are RGBA8 (linear:
psyop's pixel values reach the display unchanged, as in its PNGs) at the runtime's recommended
size per eye. The OpenGL context is psyop's own, bound to the session through EGL or GLX/Xlib
(:mod:`psyop.devices.xr.binding`).
"""

from __future__ import annotations

import ctypes
import math
import sys
import time
from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

from psyop.session.rows import JsonObject
from psyop.optics.camera import ViewGeometry
from psyop.session.frames import DisplayInterrupted, FrameRequest, RenderTarget
from psyop.devices.xr.binding import XrObject, choose_binding, create_context
from psyop.devices.xr.views_used import ViewsSeen
from psyop.devices.xr.runtime import (
    FOCUS_TIMEOUT_S,
    XrPose,
    XrRuntime,
    import_xr,
    quaternion_multiply,
    rotate,
    runtime_extensions,
    signals_held,
    tangents_from_fov,
    xr_error,
)

if TYPE_CHECKING:
    import moderngl

    from psyop.session.clock import RealClock
    from psyop.session.plan import SessionPlan


GL_RGBA8 = 0x8058
#: a target is cleared to this grey before each frame (what a phase that draws nothing shows)
CLEAR_GREY = 0.5


@dataclass
class _EyeSwapchain:
    handle: XrObject
    width_px: int
    height_px: int
    framebuffers: list[XrObject]
    acquired: bool = False


@dataclass(frozen=True)
class XrFrame:
    """The runtime's side of a frame: its times (ns) and the views to submit with the layer."""

    predicted_display_time_ns: int
    predicted_period_ns: int
    should_render: bool
    layer_views: tuple[XrObject, ...]  # XrView in the reference space, per eye (pose + fov for the layer)


class OpenXRDisplay:
    """Implements the loop's Display on an OpenXR runtime (module docstring)."""

    name = "openxr"
    paced = True

    def __init__(self, plan: SessionPlan, clock: RealClock, *, reference_space: str = "local", graphics: str = "auto",
                 request_exit_at_frame: int | None = None) -> None:
        #: a testing aid (``psyop run --xr-request-exit-at-frame N``, hidden): ask the runtime to end the
        #: session at frame N, so the tests see the real runtime take the session out of focus and stop it
        self._request_exit_at_frame = request_exit_at_frame
        self._plan, self._clock = plan, clock
        self._swapchains: dict[str, _EyeSwapchain] = {}
        choice = choose_binding(runtime_extensions(import_xr()), graphics)
        if isinstance(choice, str):
            raise xr_error(choice, "unsupported")
        try:
            self._ctx = create_context(choice.api)
        except Exception as exc:  # re-raised as a one-line UserError: no EGL device, or no GLX on $DISPLAY
            raise xr_error(f"psyop could not create its OpenGL context for the {choice.api} binding", exc) from exc
        try:
            self.runtime = XrRuntime(self._ctx, choice, reference_space=reference_space)
        except BaseException:
            self._ctx.release()
            raise
        self.xr = self.runtime.xr
        self._eyes = plan.rig.eyes
        self._index = 0
        self._frame: XrFrame | None = None  # the frame xrWaitFrame gave and xrEndFrame has not ended
        self._frame_begun = False
        self._last_display_ns: int | None = None
        self.head_pose: XrPose | None = None  # VIEW space in the reference space at the frame's display time
        self.head_pose_time_s = math.nan
        #: set by a response source that answers with the controllers (``--responses openxr``): the first
        #: trial waits until one is active, or the session ends with one line (:meth:`_wait_for_controller`)
        self.needs_controller = False
        self.frame_time_ns: int | None = None  # the current frame's predicted display time (XrTime)
        self.frames_not_rendered = 0
        self.frames_missed = 0
        self.wait_frame_s = 0.0  # time blocked in xrWaitFrame (the runtime pacing the loop)
        self.views_seen = ViewsSeen()  # what the runtime really showed (session.json's display_used)
        try:
            self._offset_ns = self.runtime.xr_time_now_ns()
            self._swapchains = self._create_swapchains()
        except Exception as exc:  # re-raised as a one-line UserError after closing
            self.close()
            raise xr_error("creating the swapchains failed", exc, self.runtime.facts.runtime) from exc
        except BaseException:  # a Ctrl-C during the start: close the runtime before it propagates
            self.close()
            raise

    # -- time ---------------------------------------------------------------------------------------
    def to_session_s(self, xr_time_ns: int) -> float:
        """A runtime time on the session clock (RealClock: perf_counter_ns since its epoch)."""
        return (int(xr_time_ns) - self._offset_ns - self._clock.epoch_ns) * 1e-9

    def to_xr_ns(self, session_s: float) -> int:
        return int(round(session_s * 1e9)) + self._clock.epoch_ns + self._offset_ns

    # -- set-up ---------------------------------------------------------------------------------------
    @signals_held
    def _create_swapchains(self) -> dict[str, _EyeSwapchain]:
        xr = self.xr
        formats = list(xr.enumerate_swapchain_formats(self.runtime.session))
        if GL_RGBA8 not in formats:
            raise RuntimeError(f"the runtime offers no RGBA8 swapchain (formats {[hex(f) for f in formats]})")
        out = {}
        for eye, (w, h) in zip(("left", "right"), self.runtime.facts.recommended_sizes_px):
            handle = xr.create_swapchain(self.runtime.session, xr.SwapchainCreateInfo(
                usage_flags=xr.SwapchainUsageFlags.COLOR_ATTACHMENT_BIT | xr.SwapchainUsageFlags.TRANSFER_DST_BIT,
                format=GL_RGBA8, sample_count=1, width=w, height=h, face_count=1, array_size=1, mip_count=1))
            images = xr.enumerate_swapchain_images(handle, xr.SwapchainImageOpenGLKHR)
            fbos = [self._ctx.framebuffer(color_attachments=[self._ctx.external_texture(img.image, (w, h), 4, 0, "f1")])
                    for img in images]
            out[eye] = _EyeSwapchain(handle, w, h, fbos)
        return out

    @property
    def gl_context(self) -> moderngl.Context | None:
        return self._ctx

    # -- the frame seam -------------------------------------------------------------------------------
    def wait_until_ready(self) -> None:
        """Submit empty frames until the runtime focuses the session (a trial starts only then)."""
        deadline = time.monotonic() + FOCUS_TIMEOUT_S
        while True:
            self.runtime.poll_events()
            if self.runtime.lost:
                raise DisplayInterrupted(self.runtime.lost, rerun=False)
            if self.runtime.focused:
                if self.needs_controller:
                    self._wait_for_controller()
                return
            if time.monotonic() > deadline:
                raise xr_error(f"the session never became FOCUSED within {FOCUS_TIMEOUT_S:g} s (state "
                               f"{self.runtime.state.name})", "is the headset on and the app in front?",
                               self.runtime.facts.runtime)
            if self.runtime.running:
                self._empty_frame()
            else:
                time.sleep(0.005)

    def _wait_for_controller(self) -> None:
        """Before the first trial of a session answered with the controllers: wait (submitting empty
        frames, input synced) until the runtime binds a controller to either hand, else end with one
        line, exit 3 (the session finalised as incomplete: a rerun resumes). A runtime without controllers recorded every trial as a timeout and said
        'complete'."""
        from psyop.devices.xr import runtime as xr_runtime

        timeout_s = xr_runtime.CONTROLLER_TIMEOUT_S
        deadline = time.monotonic() + timeout_s
        said = False
        while True:
            self.runtime.sync_actions()
            if self.runtime.active_controllers():
                self.needs_controller = False
                return
            if time.monotonic() > deadline:
                raise DisplayInterrupted(  # ends the session before its first trial, finalised and resumable: exit 3
                    f"{self.runtime.facts.runtime}: no controller became active within {timeout_s:g} s, and "
                    "--responses openxr answers with the controllers' buttons; switch a controller on (or pair it) "
                    "and run again, or answer with --responses keyboard --experimenter-window (keys typed in the "
                    "experimenter's window) or --responses serial:DEVICE", rerun=False)
            if not said:
                print(f"psyop run: waiting up to {timeout_s:g} s for a controller to become active "
                      "(--responses openxr)", file=sys.stderr, flush=True)
                said = True
            self.runtime.poll_events()
            if self.runtime.lost:
                raise DisplayInterrupted(self.runtime.lost, rerun=False)
            self._empty_frame()

    @signals_held
    def _wait_and_begin(self) -> XrObject:
        """xrWaitFrame then xrBeginFrame, with the frame marked open from the moment the wait
        returns: a Ctrl-C (or an error) between the two calls, or before xrEndFrame, leaves a frame
        that :meth:`close` begins and ends, for a second xrWaitFrame would block for ever."""
        xr = self.xr
        state = xr.wait_frame(self.runtime.session)
        self._frame = XrFrame(int(state.predicted_display_time), int(state.predicted_display_period), False, ())
        self._frame_begun = False
        xr.begin_frame(self.runtime.session)
        self._frame_begun = True
        return state

    @signals_held
    def _empty_frame(self) -> None:
        xr = self.xr
        state = self._wait_and_begin()
        xr.end_frame(self.runtime.session, xr.FrameEndInfo(display_time=state.predicted_display_time,
                                                           environment_blend_mode=xr.EnvironmentBlendMode.OPAQUE))
        self._frame = None

    @signals_held
    def begin_frame(self, not_before_s: float) -> FrameRequest:
        xr, rt = self.xr, self.runtime
        rt.poll_events()
        if rt.lost:
            raise DisplayInterrupted(rt.lost, rerun=False)
        if not rt.focused:
            raise DisplayInterrupted(f"the headset session lost focus (state {rt.state.name})", rerun=True)
        if self._request_exit_at_frame is not None and self._index == self._request_exit_at_frame:
            xr.request_exit_session(rt.session)
        waited = time.perf_counter()
        state = self._wait_and_begin()
        self.wait_frame_s += time.perf_counter() - waited
        t_ns, period_ns = int(state.predicted_display_time), int(state.predicted_display_period)
        missed = 0
        if self._last_display_ns is not None and period_ns > 0:
            missed = max(0, int(round((t_ns - self._last_display_ns) / period_ns)) - 1)
        self._last_display_ns = t_ns
        self.frames_missed += missed
        self.views_seen.add_frame(t_ns, period_ns)
        rt.sync_actions()
        self.frame_time_ns = t_ns
        self.head_pose = rt.locate(rt.head, rt.world, t_ns)
        self.head_pose_time_s = self.to_session_s(t_ns)
        should_render = bool(state.should_render)
        views: tuple[ViewGeometry, ...] = ()
        layer_views: tuple[XrObject, ...] = ()
        targets: dict[str, RenderTarget] = {}
        if should_render:
            _, in_head = xr.locate_views(rt.session, xr.ViewLocateInfo(
                view_configuration_type=rt.view_config, display_time=t_ns, space=rt.head))
            _, in_world = xr.locate_views(rt.session, xr.ViewLocateInfo(
                view_configuration_type=rt.view_config, display_time=t_ns, space=rt.world))
            located = tuple(_view_geometry(eye, v) for eye, v in zip(("left", "right"), in_head))
            self.views_seen.add_views(located)
            views = self._plan.rig.place_views(located)
            layer_views = tuple(in_world)
            for eye, chain in self._swapchains.items():
                index = xr.acquire_swapchain_image(chain.handle, xr.SwapchainImageAcquireInfo())
                xr.wait_swapchain_image(chain.handle, xr.SwapchainImageWaitInfo(timeout=xr.INFINITE_DURATION))
                chain.acquired = True
                fbo = chain.framebuffers[index]
                fbo.clear(CLEAR_GREY, CLEAR_GREY, CLEAR_GREY, 1.0)
                if eye in self._eyes:
                    targets[eye] = RenderTarget(fbo, chain.width_px, chain.height_px)
        else:
            self.frames_not_rendered += 1
        self._frame = XrFrame(t_ns, period_ns, should_render, layer_views)
        self._index += 1
        return FrameRequest(self._index - 1, self.to_session_s(t_ns), period_ns * 1e-9, should_render,
                            views=tuple(v for v in views if v.eye in self._eyes), targets=targets, missed_frames=missed)

    @signals_held
    def end_frame(self, frame: FrameRequest, images: Sequence[moderngl.Texture]) -> float:
        xr, rt = self.xr, self.runtime
        pending = self._frame  # cleared only once xrEndFrame returns: close() ends a frame left open
        layers = []
        if pending is not None and pending.should_render:
            self._ctx.finish()  # the images are complete before the runtime reads them
            projection_views = []
            for (eye, chain), view in zip(self._swapchains.items(), pending.layer_views):
                if chain.acquired:
                    xr.release_swapchain_image(chain.handle, xr.SwapchainImageReleaseInfo())
                    chain.acquired = False
                projection_views.append(xr.CompositionLayerProjectionView(
                    pose=view.pose, fov=view.fov, sub_image=xr.SwapchainSubImage(
                        swapchain=chain.handle,
                        image_rect=xr.Rect2Di(extent=xr.Extent2Di(chain.width_px, chain.height_px)))))
            layer = xr.CompositionLayerProjection(space=rt.world, views=projection_views)
            layers = [ctypes.byref(layer)]
        display_ns = pending.predicted_display_time_ns if pending is not None else self.to_xr_ns(self._clock.now_s())
        xr.end_frame(rt.session, xr.FrameEndInfo(display_time=display_ns,
                                                 environment_blend_mode=xr.EnvironmentBlendMode.OPAQUE, layers=layers))
        self._frame = None
        return self._clock.now_s()

    def views_used(self) -> JsonObject:
        """The run's ``display_used`` block: the runtime's swapchain sizes, fields of view and measured rate."""
        facts = self.runtime.facts
        return self.views_seen.record(facts.recommended_sizes_px, facts.runtime, facts.system)

    def summary(self) -> JsonObject:
        facts = self.runtime.facts
        return {"display": self.name, "runtime": facts.runtime, "system": facts.system, "extensions": facts.extensions,
                "eye_gaze_supported": facts.eye_gaze_supported, "swapchain_sizes_px": facts.recommended_sizes_px,
                "reference_space": facts.reference_space, "graphics": facts.graphics, "frames": self._index,
                "frames_not_rendered": self.frames_not_rendered, "frames_missed": self.frames_missed,
                "wait_frame_s": self.wait_frame_s,
                "session_states": list(facts.states)}

    @signals_held
    def close(self) -> None:
        rt = self.runtime
        if self._ctx is not None:
            # GL is asynchronous: draws into a swapchain image may still be rasterising (llvmpipe's
            # threads, or a GPU) when a Ctrl-C lands mid-frame. Destroying the swapchains, session or
            # instance frees the runtime-owned memory those images live in, and the raster threads
            # then write into freed memory (SIGSEGV). Wait for every queued draw first.
            try:
                self._ctx.finish()
            except Exception:  # noqa: BLE001 - teardown goes on
                pass
        if rt.session is not None:
            for chain in self._swapchains.values():
                if chain.acquired:
                    try:
                        self.xr.release_swapchain_image(chain.handle, self.xr.SwapchainImageReleaseInfo())
                    except Exception:  # noqa: BLE001 - teardown goes on
                        pass
                    chain.acquired = False
            if self._frame is not None:  # a frame waited for and never ended (an error mid-frame)
                open_frame, self._frame = self._frame, None
                try:
                    if not self._frame_begun:
                        self.xr.begin_frame(rt.session)
                    self.xr.end_frame(rt.session, self.xr.FrameEndInfo(
                        display_time=open_frame.predicted_display_time_ns,
                        environment_blend_mode=self.xr.EnvironmentBlendMode.OPAQUE))
                except Exception:  # noqa: BLE001 - teardown goes on
                    pass
            rt.request_exit(self._empty_frame)
            for chain in self._swapchains.values():
                for fbo in chain.framebuffers:
                    fbo.release()
                try:
                    self.xr.destroy_swapchain(chain.handle)
                except Exception:  # noqa: BLE001
                    pass
            self._swapchains = {}
        rt.close()
        if self._ctx is not None:
            self._ctx.release()
            self._ctx = None  # type: ignore[assignment]  # released on close; nothing renders in it again


def _view_geometry(eye: str, view: XrObject) -> ViewGeometry:
    p, q = view.pose.position, view.pose.orientation
    return ViewGeometry(eye, (float(p.x), float(p.y), float(p.z)), (float(q.w), float(q.x), float(q.y), float(q.z)),
                        tangents_from_fov(view.fov))


def open_openxr_display(plan: SessionPlan, clock: RealClock, request_exit_at_frame: int | None = None,
                        graphics: str = "auto") -> OpenXRDisplay:
    """The OpenXR display for a session of ``plan`` on ``clock`` (a RealClock); ``graphics``: the
    OpenGL binding, ``auto``, ``egl`` or ``xlib`` (:mod:`psyop.devices.xr.binding`)."""
    return OpenXRDisplay(plan, clock, graphics=graphics, request_exit_at_frame=request_exit_at_frame)


__all__ = ["OpenXRDisplay", "open_openxr_display", "quaternion_multiply", "rotate"]
