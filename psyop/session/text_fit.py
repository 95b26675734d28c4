"""Legible text on the session's display, checked before the first trial.

A session that draws text (the response phase's prompt, the ``session:`` screens) lays every string out on the
display it renders to (psyop.rendering.text.layout_text: capitals of at least MIN_CAP_HEIGHT_PX device pixels and
one em of at least MIN_EM_DEG, wrapped to stay inside each eye's view). :func:`session_texts` builds the session's
:class:`~psyop.rendering.text.TextImages` for that display and, when text is drawn, lays out every text the
protocol can show first: one that cannot fit is refused with a :class:`~psyop.errors.UserError` at the protocol
line it is written on, before any trial runs. A headset draws each eye into the runtime's own images, whose size
and field of view the first frame brings (:func:`refit_texts`): the texts are laid out and checked again for them
there, at the session's first frame.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

from psyop.errors import UserError
from psyop.optics.display import DisplayProfile
from psyop.protocol.trial import ResponsePhase
from psyop.rendering.text import EyeView, TextDoesNotFit, TextImages, display_views
from psyop.session.frames import FrameRequest
from psyop.session.plan import SessionPlan
from psyop.session.rating_stick import marked_texts
from psyop.session.screens import page_pictures, screen_texts
from psyop.stimulus.build import TEXT_DISTANCE_M, scene_origin_m

#: a protocol path (keys and list indices) and the text written there
PathText = tuple[tuple[str | int, ...], str]


def panel_offset_tan(plan: SessionPlan, eye: str, camera_centre_m: ArrayLike | None = None) -> float:
    """The tangent, right positive, of the text panel's centre (straight ahead of the scene origin at
    TEXT_DISTANCE_M) seen from ``eye``'s camera (``camera_centre_m``: where a headset runtime puts it; None: the
    rig's eye centre): 0 when monocular, about half the ipd over 1 m in stereo (the panel's disparity)."""
    rig_centre = np.asarray(plan.rig.centre_m(eye), dtype=np.float64).reshape(3)
    centre = rig_centre if camera_centre_m is None else np.asarray(camera_centre_m, dtype=np.float64).reshape(3)
    origin = scene_origin_m(plan.protocol, rig_centre)
    depth_m = TEXT_DISTANCE_M + float(centre[2] - origin[2])
    return float(origin[0] - centre[0]) / depth_m


def panel_offsets_tan(plan: SessionPlan) -> dict[str, float]:
    """:func:`panel_offset_tan` of each eye of the plan, from the rig's eye centres."""
    return {eye: panel_offset_tan(plan, eye) for eye in plan.rig.eyes}


def frame_views(plan: SessionPlan, display: DisplayProfile, frame: FrameRequest) -> tuple[EyeView, ...] | None:
    """The views a headset frame draws into: per eye its swapchain image's size, the runtime's field of view
    (else the profile's) and the panel's place seen from the runtime's eye centre, rounded (0.1 mrad, 1 um) so that
    a runtime's per-frame jitter does not count as a new display; None when the frame has no targets of its own."""
    if not frame.targets:
        return None
    views = []
    for eye in plan.rig.eyes:
        target, view = frame.targets.get(eye), frame.view(eye)
        width, height = (target.width_px, target.height_px) if target is not None else (display.width_px,
                                                                                          display.height_px)
        tangents = view.tangents if view is not None else display.frustum_tangents(eye)
        offset = panel_offset_tan(plan, eye, None if view is None else view.centre_m)
        views.append(EyeView(int(width), int(height), tuple(round(float(t), 4) for t in tangents),  # type: ignore[arg-type]
                             round(offset, 6)))
    return tuple(views)


def protocol_texts(plan: SessionPlan) -> list[tuple[PathText, bool]]:
    """Every text the session can draw, with its protocol path and whether its line breaks are kept: the
    response phase's text (its ``prompt``, else the ``question``), then every session screen's."""
    out: list[tuple[PathText, bool]] = []
    response = plan.response
    text = response.participant_text
    if text is not None:
        phases = plan.protocol.trial.phases
        index = next((i for i, p in enumerate(phases) if isinstance(p, ResponsePhase)), None)
        given = response.prompt is not None and response.prompt.strip() and index is not None
        path: tuple[str | int, ...] = ("trial", "phases", index, "prompt") if given and index is not None \
            else ("response", "question")
        out.append(((path, text), response.keeps_lines))
        out += [((("response", "scale"), marked), True) for marked in marked_texts(plan)]  # the stick's marker
    if plan.protocol.session is not None:
        out += [(item, True) for item in screen_texts(plan.protocol.session)]
    return out


def session_texts(plan: SessionPlan, display: DisplayProfile, *, drawn: bool = True,
                  views: tuple[EyeView, ...] | None = None) -> TextImages:
    """The session's text images, laid out legibly on ``display`` (the profile at the size it is rendered,
    e.g. scaled to the window) or on ``views`` (a headset's, :func:`frame_views`). ``drawn``: text is shown (a
    person watches), so every text of the protocol is laid out now and one that cannot fit raises UserError naming
    its protocol line, the view's size and the fix."""
    views = views if views is not None else display_views(display, panel_offsets_tan(plan))
    texts = TextImages(views=views)
    if not drawn:
        return texts
    sizes = " and ".join(sorted({f"{v.width_px}x{v.height_px} px" for v in views}))
    for (path, text), keep_lines in protocol_texts(plan):
        try:
            texts.layout(text, keep_lines)
        except TextDoesNotFit as error:
            raise UserError(f"on a {sizes} view, {error}", _location(plan, path)) from None
    for where, text, picture in page_pictures(plan):  # an instruction page's picture above its text
        try:
            texts.page(text, picture)
        except TextDoesNotFit as error:
            raise UserError(f"on a {sizes} view, {error}", _location(plan, where)) from None
    return texts


def refit_texts(texts: TextImages, plan: SessionPlan, display: DisplayProfile, frame: FrameRequest | None) -> TextImages:
    """``texts``, or, when ``frame`` draws into a headset's own images whose views differ from those ``texts`` was
    laid out for, the session's texts laid out (and checked, :func:`session_texts`) on the frame's views."""
    views = None if frame is None else frame_views(plan, display, frame)
    if views is None or views == texts.views:
        return texts
    return session_texts(plan, display, views=views)


def _location(plan: SessionPlan, path: tuple[str | int, ...]) -> str:
    """``file:line:column`` of ``path`` in the protocol's text (the file alone when it has no text)."""
    from psyop.protocol.source import read_yaml

    protocol = plan.protocol
    name = protocol.source_name or plan.study
    if not protocol.source_text:
        return name
    document = read_yaml(protocol.source_text, name)
    _, mark = document.nearest(path)
    return document.location(mark)
