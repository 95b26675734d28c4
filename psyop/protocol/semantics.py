"""Checks that need the whole protocol (or the file system), after each section is valid.

Each finding is an :class:`Issue` with the key path it concerns and a message that says what
to change; the loader maps the path to file:line:column.
"""

from __future__ import annotations

import difflib
import math
from dataclasses import dataclass
from pathlib import Path as FsPath
from collections.abc import Iterator, Mapping
from typing import TYPE_CHECKING

from pydantic import BaseModel

from psyop.errors import UserError
from psyop.images import check_image_file
from psyop.limits import MAX_MESH_TRIANGLES, MAX_PRIMITIVES
from psyop.optics.ranges import DEPTH_D
from psyop.protocol.base import UNIT_SUFFIXES, has_unit_suffix
from psyop.protocol.conditions import expand_conditions
from psyop.protocol.model import Protocol
from psyop.protocol.kinds import kind_of
from psyop.protocol.kinds.confidence import check_confidence
from psyop.protocol.kinds.two_interval import TwoIntervalResponse
from psyop.protocol.primitive_count import primitive_count
from psyop.protocol.scene import (RENDERING_MODES, Depth, FactorRef, FixationTarget, ImageSurface, LevelRef, Mesh,
                                  PinkNoiseSurface, ReachMesh, ReachTarget, Room, SinusoidalBorder,
                                  TargetField,
                                  centre_eccentricity_deg)
from psyop.protocol.trial import Blank, Interval, ResponsePhase
from psyop.records import JsonObject, Loc

if TYPE_CHECKING:
    from psyop.mesh.load import MeshFiles

#: Random sequential placement of equal discs jams at about 54.7 % area coverage. Measured for
#: 2.6 deg targets in a 60 deg field (centres within field/2 - size/2): 40 % coverage needs about
#: 1.3k tries, 45 % about 3.3k, 50 % about 15k. Above 40 % a per-trial placement gets slow.
MAX_RANDOM_COVERAGE = 0.4

# ---- ADAPTIVE LEVELS ----------------------------------------------------------------------------
#: Names of the adaptive procedures the session runs (``level_D: {adaptive: {procedure: ...}}``,
#: psyop.adaptive.session); any other name is refused at validation with its file:line.
ADAPTIVE_PROCEDURES: frozenset[str] = frozenset({"quest_plus", "staircase"})



#: Where an issue is: a :data:`~psyop.records.Loc`, whose keys may also be numbers (a ``levels_by`` key is
#: the parent factor's level, a YAML number; the loader finds it in the file as written).
IssuePath = tuple[str | int | float, ...]


@dataclass(frozen=True)
class Issue:
    """One problem: where (key path) and what to do."""

    path: IssuePath
    message: str


def _suggest(name: str, options: list[str]) -> str:
    close = difflib.get_close_matches(name, options, n=1)
    return f" Did you mean '{close[0]}'?" if close else ""


class _Checker:
    def __init__(self, protocol: Protocol, base_dir: FsPath | None, meshes: MeshFiles | None = None) -> None:
        self.p = protocol
        self.base_dir = base_dir
        self.meshes = meshes  # the models read by check_mesh (a fresh MeshFiles when None)
        self.issues: list[Issue] = []
        self.factors = protocol.design.factors
        # per-trial variables the scene may read though no factor (an adjustment's): name -> its range
        self.variables = protocol.response.scene_variables()
        # mesh item id -> triangles of each (file, node) it can show (read by check_mesh)
        self.mesh_triangles: dict[str, dict[tuple[str, str | None], int]] = {}

    def add(self, path: IssuePath, message: str) -> None:
        self.issues.append(Issue(path, message))

    # -- factors ------------------------------------------------------------------------------
    def factor_exists(self, name: str, path: Loc, *, numeric: bool | None = None) -> bool:
        if name in self.variables and name not in self.factors:  # a number the response sets per trial
            if numeric is False:
                self.add(path, f"'{name}' is the response's adjusted variable, a number; words are needed here")
            return numeric is not False
        if name not in self.factors:
            self.add(path, f"'{name}' is not a factor of design.factors.{_suggest(name, list(self.factors))} "
                           f"Factors: {', '.join(self.factors)}")
            return False
        if numeric is not None and self.factors[name].is_numeric != numeric:
            kind = "numbers" if numeric else "words"
            self.add(path, f"factor '{name}' must have {kind} as levels here")
            return False
        return True

    def check_factors(self) -> None:
        for name, factor in self.factors.items():
            path = ("design", "factors", name)
            if factor.adaptive is not None and factor.adaptive.procedure not in ADAPTIVE_PROCEDURES:
                known = ", ".join(sorted(ADAPTIVE_PROCEDURES)) or "none in this version of psyop"
                self.add(path + ("adaptive", "procedure"),
                         f"adaptive procedure '{factor.adaptive.procedure}' is not available (available: {known}); "
                         "give fixed levels instead, e.g. levels: {start: 0, step: 0.25, count: 7}")
            elif factor.adaptive is not None:
                self.check_adaptive(name, path)
            if factor.is_numeric and not has_unit_suffix(name):
                self.add(path, f"numeric factor '{name}' must say its unit in its name: end it with one of "
                               f"{', '.join(UNIT_SUFFIXES)} (e.g. '{name}_D')")
            if not factor.is_numeric and has_unit_suffix(name) and name.endswith(("_D", "_m", "_deg", "_s")):
                self.add(path, f"factor '{name}' has a unit suffix but its levels are words; give numbers or rename")
            if factor.depends_on is None:
                continue
            parent_name = factor.depends_on
            if parent_name == name:
                self.add(path + ("depends_on",), "a factor cannot depend on itself")
                continue
            if not self.factor_exists(parent_name, path + ("depends_on",)):
                continue
            parent = self.factors[parent_name]
            if parent.depends_on is not None:
                self.add(path + ("depends_on",), f"'{parent_name}' itself depends on another factor; nest one level only")
                continue
            if parent.adaptive is not None:
                self.add(path + ("depends_on",), f"'{parent_name}' is adaptive; levels cannot depend on it")
                continue
            parent_levels = parent.levels_for(None)
            assert factor.levels_by is not None
            for key in factor.levels_by:
                if not any(_same(key, level) for level in parent_levels):
                    self.add(path + ("levels_by", key), f"{key!r} is not a level of '{parent_name}' "
                                                       f"(levels: {parent_levels}); fix or remove this entry")
            for level in parent_levels:
                if not any(_same(key, level) for key in factor.levels_by):
                    self.add(path + ("levels_by",), f"no levels given for {parent_name} = {level!r}; add "
                                                    f"'{level}: [...]' under levels_by")
        randomisation = self.p.design.randomisation
        for index, name in enumerate(randomisation.by):
            self.factor_exists(name, ("design", "randomisation", "by", index))

    # -- scene -------------------------------------------------------------------------------
    def depth_refs(self, depth: Depth, path: Loc) -> bool:
        ok = True
        names = depth.factor_names
        for name in names:
            if not self.factor_exists(name, path + ("factor",), numeric=True):
                ok = False
                continue
            metric = name.endswith("_m")
            if not (name.endswith("_D") or metric) or (metric and (len(names) > 1 or depth.D is not None)):
                self.add(path + ("factor",), f"depth factor '{name}' must be in dioptres (name ending in _D), or "
                                             "a single factor in metres (_m) with no D")
                ok = False
        return ok

    def check_adaptive(self, name: str, path: Loc) -> None:
        """The procedures model a 2AFC psychometric function of the response's level."""
        response = self.p.response
        if not isinstance(response, TwoIntervalResponse) or response.level_factor != name:
            self.add(path + ("adaptive",), f"adaptive procedures place the level of a two_interval response; "
                                           f"'{name}' must be response.level_factor of a two_interval response")
        adaptive = [n for n, f in self.factors.items() if f.adaptive is not None]
        if len(adaptive) > 1 and name == adaptive[1]:
            self.add(path + ("adaptive",), f"only one adaptive factor per protocol (found {', '.join(adaptive)})")

    def check_scene(self, conditions: list[JsonObject]) -> None:
        ids: dict[str, int] = {}
        for index, item in enumerate(self.p.scene):
            path = ("scene", index)
            if item.id in ids:
                self.add(path + ("id",), f"id '{item.id}' is already used by scene[{ids[item.id]}]; ids must be unique")
            ids.setdefault(item.id, index)
            for name in ("depth", "near", "far", "near_depth", "far_depth"):
                depth = getattr(item, name, None)
                if isinstance(depth, Depth) and self.depth_refs(depth, path + (name,)):
                    self.check_depth_values(depth, path + (name,), conditions)
            for surface_name in ("surface", "left", "right"):
                surface = getattr(item, surface_name, None)
                if isinstance(surface, ImageSurface):
                    self.check_image(surface, path + (surface_name, "path"))
                if isinstance(surface, PinkNoiseSurface) and surface.exponent != 1.0:
                    self.add(path + (surface_name, "exponent"), f"exponent {surface.exponent:g} is not rendered: only 1/f "
                                                                "noise (exponent: 1) is implemented; use 1 or white_noise")
            if isinstance(item, Room) and item.table_height_m is not None and item.table_height_m >= item.height_m:
                self.add(path + ("table_height_m",), "the table is as high as the room; make table_height_m less than height_m")
            if isinstance(item, Room) and item.eye_height_m >= item.height_m:
                self.add(path + ("eye_height_m",), "the eyes are above the ceiling; make eye_height_m less than height_m")
            if isinstance(item, TargetField):
                self.check_target_field(item, path, conditions)
            if isinstance(item, Mesh) or (isinstance(item, ReachTarget) and isinstance(item.object, ReachMesh)):
                self.check_mesh(item, path, conditions)
            if isinstance(item, SinusoidalBorder):
                self.check_order(item.near_depth, item.far_depth, path + ("near_depth",), conditions,
                                 "near_depth must be nearer (more dioptres) than far_depth")
                if item.amplitude_deg * 2 >= item.size_deg:
                    self.add(path + ("amplitude_deg",), "the border swings wider than the surfaces; make "
                                                        "amplitude_deg less than half of size_deg")
                if item.near_side == "schedule" and self.p.response.kind != "left_right_nearer":
                    self.add(path + ("near_side",), "near_side: schedule needs a left_right_nearer response; "
                                                    "set near_side to left or right")
            self.check_factor_fields(item, path, conditions)
            if isinstance(item, ReachTarget) and isinstance(item.distance_fraction, FactorRef):
                self.factor_exists(item.distance_fraction.factor, path + ("distance_fraction", "factor"), numeric=True)
            if isinstance(item, FixationTarget) and item.path is not None:
                self.check_fixation_field(item, path, conditions)
        for index, phase in enumerate(self.p.trial.phases):
            if isinstance(phase, (Interval, Blank)) and isinstance(phase.show, list):
                for j, name in enumerate(phase.show):
                    if name not in ids:
                        self.add(("trial", "phases", index, "show", j),
                                 f"no scene primitive has id '{name}'.{_suggest(name, list(ids))} Ids: {', '.join(ids)}")

    def check_fixation_field(self, item: FixationTarget, path: Loc,
                             conditions: list[JsonObject]) -> None:
        """The circling target stays in the forward field for every level of a centre or path factor."""
        from psyop.protocol.factor_fields import factor_fields, resolve_factor_fields

        value_sets = self._value_sets(conditions) if any(True for _ in factor_fields(item)) else iter([{}])
        for values in value_sets:
            try:
                resolved = resolve_factor_fields(item, values)
                centre_ecc = centre_eccentricity_deg(resolved.centre_deg)
                reach = centre_ecc + float(resolved.path.eccentricity_deg)
            except (ValueError, TypeError):  # an adaptive level not yet known (its ends come next), a bad level:
                continue                     # reported by check_factor_fields
            if not math.isnan(reach) and reach + float(item.size_deg) / 2 >= 90:
                self.add(path + ("path", "eccentricity_deg"),
                         f"the fixation path reaches {reach:g} deg from straight ahead and leaves the forward field; "
                         "make centre_deg plus eccentricity_deg less than 90")
                return

    def check_visibility(self, conditions: list[JsonObject]) -> None:
        """A fixation target or stimulus an aperture hides in every frame that shows it (psyop.protocol.visibility)."""
        from psyop.protocol.visibility import hidden_by_aperture

        for path, message in hidden_by_aperture(self.p, conditions):
            self.add(path, message)

    def _value_sets(self, conditions: list[JsonObject]) -> Iterator[JsonObject]:
        """Every set of factor values a scene is built from: each condition, each interval's ``set:``
        overrides of it, and an adaptive factor at both ends of its range."""
        adaptive = {n: f.adaptive for n, f in self.factors.items() if f.adaptive is not None}
        overrides: list[dict[str, float]] = [{}]
        overrides += [dict(spec.set) for spec in self.p.response.interval_specs() if spec.set]
        for condition in conditions:
            ends: list[dict[str, float]] = [{}] + [{n: float(a.min)} for n, a in adaptive.items()] + \
                [{n: float(a.max)} for n, a in adaptive.items()]
            for end in ends:
                for override in overrides:
                    yield {**condition, **end, **override}

    def check_factor_fields(self, item: BaseModel, path: Loc, conditions: list[JsonObject]) -> None:
        """Each ``{factor: NAME}`` of a size or contrast names a numeric factor, and every level it can take
        fits the field's range (the item is re-validated with each trial's values)."""
        from pydantic import ValidationError

        from psyop.protocol.factor_fields import factor_fields, resolve_factor_fields

        refs = [(sub, ref) for sub, ref in factor_fields(item) if sub != ("distance_fraction",)]
        if not refs or not all(self.factor_exists(ref.factor, path + sub + ("factor",), numeric=True)
                               for sub, ref in refs):
            return
        for values in self._value_sets(conditions):
            try:
                type(item).model_validate(resolve_factor_fields(item, values).model_dump())
            except ValidationError as error:
                first = error.errors()[0]
                sub, ref = next(((sub, r) for sub, r in refs if _in_order(sub, tuple(first["loc"]))), refs[0])
                self.add(path + sub, f"{ref.factor} = {values.get(ref.factor)!r} does not fit this field: "
                                     f"{first['msg'].lower()}; give {ref.factor} levels (or an adaptive range) that do")
                return
            except ValueError:  # an adaptive level, known at run time: its range's ends are checked next
                continue

    def check_mesh(self, item: Mesh | ReachTarget, path: Loc, conditions: list[JsonObject]) -> None:
        """Every model the item (a mesh, or a reach target whose object is one) can show is read now
        (psyop.mesh.load: every file-level problem is one line at the item's ``file`` or ``node``, naming the
        factor level that picks it), and a mesh at optical infinity is refused (a model has a place, not only
        directions). ``{factor: NAME}`` on file/node: a factor of words."""
        from psyop.mesh.load import MeshFiles
        from psyop.protocol.mesh_models import item_models, level_note, model_source

        found = model_source(item)
        assert found is not None  # called for items that name a model
        source, below = found
        path = path + below
        if not all(self.factor_exists(factor, path + (field, "factor"), numeric=False)
                   for field, factor in source.word_factors):
            return
        base_dir = self.base_dir or FsPath.cwd()
        if self.meshes is None:
            self.meshes = MeshFiles(base_dir)
        counts: dict[tuple[str, str | None], int] = {}
        for (file, node), values in item_models(source, self._value_sets(conditions)).items():
            try:
                counts[(file, node)] = self.meshes.load(FsPath(file), node, base_dir=base_dir).triangle_count
            except UserError as error:
                field = "node" if node is not None and "node" in str(error) else "file"
                self.add(path + (field,), level_note(source, values) + str(error))
                return
        self.mesh_triangles[item.id] = counts
        if isinstance(item, Mesh) and item.depth is not None and item.depth.constant_D() == 0.0:
            self.add(path + ("depth",), "a mesh cannot lie at optical infinity (0 D); give a finite depth")

    def check_mesh_budget(self, conditions: list[JsonObject]) -> None:
        """Each phase's mesh items together hold at most MAX_MESH_TRIANGLES triangles, in every trial (a factor
        on ``file`` or ``node`` counts the models that trial's levels pick)."""
        from psyop.protocol.mesh_models import level_note, model_source

        for index, phase in enumerate(self.p.trial.phases):
            if not isinstance(phase, (Interval, Blank)) or getattr(phase, "display_off", False):
                continue
            shown = [(i, item.id, found[0]) for i, item in enumerate(self.p.scene)
                     if (found := model_source(item)) is not None and item.id in self.mesh_triangles
                     and (phase.show == "all" or item.id in phase.show)]
            varying = any(source.word_factors for _, _, source in shown)
            for values in (self._value_sets(conditions) if varying else iter([{}])):
                counts = [(self.mesh_triangles[name].get(source.model_for(values), 0), i, name, source)
                          for i, name, source in shown]
                total = sum(c[0] for c in counts)
                if total > MAX_MESH_TRIANGLES:
                    most, i, name, source = max(counts, key=lambda t: t[0])
                    self.add(("scene", i), f"{level_note(source, values)}phase trial.phases[{index}] ({phase.kind}) "
                                           f"draws {total} mesh triangles, more than the budget of {MAX_MESH_TRIANGLES} "
                                           f"(psyop.limits.MAX_MESH_TRIANGLES); '{name}' has {most}. Fix: a "
                                           "simpler model, or show fewer meshes in that phase")
                    return

    def check_primitive_limit(self) -> None:
        """Each phase's scene (its ``show:`` items) must fit the renderer's MAX_PRIMITIVES; the
        error points at the item that adds the most primitives (first phase over the limit only)."""
        for index, phase in enumerate(self.p.trial.phases):
            if not isinstance(phase, (Interval, Blank)) or getattr(phase, "display_off", False):
                continue
            shown = [(i, item) for i, item in enumerate(self.p.scene) if phase.show == "all" or item.id in phase.show]
            counts = [(primitive_count(item), i, item) for i, item in shown]
            total = sum(c for c, _, _ in counts)
            if total <= MAX_PRIMITIVES:
                continue
            most, i, item = max(counts, key=lambda t: t[0])
            where = ("scene", i, "count") if isinstance(item, TargetField) else ("scene", i)
            fix = (f"lower count to at most {most - (total - MAX_PRIMITIVES)}" if isinstance(item, TargetField)
                   else "draw fewer scene items")
            self.add(where, f"phase trial.phases[{index}] ({phase.kind}) draws {total} primitives, more than the "
                            f"renderer's limit of {MAX_PRIMITIVES} (psyop.limits.MAX_PRIMITIVES); '{item.id}' "
                            f"({item.kind}) adds {most} of them. Fix: {fix}, or show fewer items in that phase "
                            "(its show: list)")
            return

    def check_depth_values(self, depth: Depth, path: Loc, conditions: list[JsonObject]) -> None:
        for condition in conditions:
            try:
                value = depth.resolve_D(condition)
            except (ZeroDivisionError, KeyError, TypeError, ValueError):
                value = math.nan
            if math.isnan(value) and any(math.isnan(float(condition[n])) for n in depth.factor_names):
                continue  # adaptive: known only at run time
            if not DEPTH_D.contains(value):
                self.add(path, f"this depth is {value} D for condition {condition}; depths must be in "
                               f"{DEPTH_D.describe()} (0 D = optical infinity)")
                return

    def check_order(self, near: Depth, far: Depth, path: Loc, conditions: list[JsonObject],
                    message: str) -> None:
        for condition in conditions:
            try:
                near_D, far_D = near.resolve_D(condition), far.resolve_D(condition)
            except (ZeroDivisionError, KeyError, TypeError, ValueError):
                return
            if near_D <= far_D:
                self.add(path, f"{message} (here near = {near_D:g} D, far = {far_D:g} D); swap them")
                return

    def check_target_field(self, item: TargetField, path: Loc, conditions: list[JsonObject]) -> None:
        self.check_order(item.near, item.far, path + ("near",), conditions,
                         "the depth range is in the wrong order: near must be more dioptres than far")
        if item.size_deg >= item.field_deg:
            self.add(path + ("size_deg",), f"a target of {item.size_deg} deg does not fit in a {item.field_deg} deg "
                                           "field; make size_deg smaller than field_deg")
            return
        # targets' centres lie within field_deg - size_deg so each target stays inside the field
        effective = (item.size_deg + item.min_gap_deg) ** 2
        coverage = item.count * effective / (item.field_deg**2)
        if coverage > MAX_RANDOM_COVERAGE:
            fit = int(MAX_RANDOM_COVERAGE * item.field_deg**2 / effective)
            self.add(path + ("count",), f"{item.count} targets of {item.size_deg} deg (gap {item.min_gap_deg} deg) "
                                        f"cannot be placed at random without overlap in a {item.field_deg} deg field "
                                        f"(they would cover {coverage:.0%} of it; random placement becomes slow above 40 % and jams near 55 %). "
                                        f"Use at most {fit} targets, smaller targets or a wider field.")

    def check_luminance(self, conditions: list[JsonObject]) -> None:
        """The display's calibration file, every luminance against its range, gratings against the display's
        Nyquist frequency (psyop.protocol.luminance)."""
        from psyop.protocol.luminance import grating_issues, luminance_issues

        value_sets = list(self._value_sets(conditions))
        for path, message in luminance_issues(self.p, self.base_dir, value_sets) + grating_issues(self.p, value_sets):
            self.add(path, message)

    def check_image(self, surface: ImageSurface, path: Loc) -> None:
        base = self.base_dir or FsPath.cwd()
        target = (base / surface.path)
        if not target.is_file():
            self.add(path, f"texture file '{surface.path}' not found (looked for {target}); paths are relative "
                           "to the protocol file. Fix the path or add the file.")
            return
        try:  # decode it now: run, render and audit would otherwise fail on it mid-session
            check_image_file(target, surface.path)
        except UserError as error:
            self.add(path, error.message)

    # -- trial, response, observer ----------------------------------------------------------
    def check_phase_order(self) -> None:
        """One response phase, last: the session runs the phases up to it, then waits for the answer."""
        phases = self.p.trial.phases
        responses = [i for i, phase in enumerate(phases) if isinstance(phase, ResponsePhase)]
        if len(responses) != 1:
            self.add(("trial", "phases"), f"trial.phases needs exactly one '- kind: response' phase, found "
                                          f"{len(responses)}; add or remove one")
        elif responses[0] != len(phases) - 1:
            self.add(("trial", "phases", responses[0] + 1), "phases after the response phase would never run; "
                                                           "move the response phase to the end")

    def check_response(self) -> None:
        self.check_phase_order()
        response = self.p.response
        needed = response.intervals()
        intervals = len(self.p.trial.intervals)
        if intervals != needed:
            self.add(("trial", "phases"), f"a {response.kind} response needs {needed} interval phase(s), "
                                          f"but trial.phases has {intervals}; add or remove '- kind: interval'")
        kind_of(response).check(response, self, ("response",))
        check_confidence(kind_of(response), response, self.p.observer, self, ("response",))
        if response.kind != "with_against" and self.p.display.rendering_nc is not None \
                and self.p.display.rendering_nc.signed:
            self.add(("display", "rendering_nc", "signed"), "a signed rendering NC sets each trial's mode from its "
                                                           "sign: only a with_against response reads it; remove signed")

    def check_kind_design(self) -> None:
        """The design checks only the response's kind needs (psyop.protocol.kinds)."""
        kind_of(self.p.response).check_design(self.p.response, self)

    def used_factors(self) -> set[str]:
        """Every factor some part of the protocol reads: the scene (any ``{factor: ...}``), the response's
        fields, another factor's ``depends_on``, or the blocking ``by:``."""
        used: set[str] = set()
        for item in self.p.scene:
            used |= _factor_refs(item)
        used |= self.p.response.factors_read()
        used |= {f.depends_on for f in self.factors.values() if f.depends_on}
        nc = self.p.display.rendering_nc
        for value in (nc.mm, nc.scale) if nc is not None else ():
            if isinstance(value, FactorRef):
                used.add(value.factor)
        if isinstance(self.p.display.added_latency_ms, FactorRef):
            used.add(self.p.display.added_latency_ms.factor)
        return used

    def check_added_latency(self, conditions: list[JsonObject]) -> None:
        """``display.added_latency_ms: {factor: NAME}``: a numeric factor named ``..._ms`` whose every level is a
        latency in [0, MAX_ADDED_LATENCY_MS] ms (docs/latency.md)."""
        from psyop.protocol.display import MAX_ADDED_LATENCY_MS

        ref = self.p.display.added_latency_ms
        if not isinstance(ref, FactorRef):
            return
        path = ("display", "added_latency_ms", "factor")
        if not self.factor_exists(ref.factor, path, numeric=True):
            return
        if not ref.factor.endswith("_ms"):
            self.add(path, f"added_latency_ms reads milliseconds: name the factor '{ref.factor}' with _ms "
                           "(e.g. added_latency_ms)")
            return
        for level in sorted({float(c[ref.factor]) for c in conditions if ref.factor in c}):
            if not 0.0 <= level <= MAX_ADDED_LATENCY_MS:
                self.add(path, f"level {level:g} of '{ref.factor}' is no added latency in [0, "
                               f"{MAX_ADDED_LATENCY_MS:g}] ms")

    def check_rendering_nc(self, conditions: list[JsonObject]) -> None:
        """``display.rendering_nc``: a numeric factor (``mm`` ones named ``..._mm``), not a ``set:`` override,
        and every value giving an NC in psyop.optics.ranges.NC_M."""
        from psyop.optics.ranges import NC_M
        from psyop.protocol.display import rendering_nc_rule, resolve_eye_model

        nc = self.p.display.rendering_nc
        if nc is None:
            return
        key = "mm" if nc.mm is not None else "scale"
        value = nc.mm if nc.mm is not None else nc.scale
        path = ("display", "rendering_nc", key)
        rule = rendering_nc_rule(self.p.display)
        eye_nc_m = resolve_eye_model(self.p.display).nc_m
        if isinstance(value, FactorRef):
            if not self.factor_exists(value.factor, path + ("factor",), numeric=True):
                return
            if key == "mm" and not value.factor.endswith("_mm"):
                self.add(path + ("factor",), f"rendering_nc.mm reads millimetres: name the factor '{value.factor}' with "
                                             "_mm (e.g. nc_mm), or use rendering_nc: {scale: {factor: ...}}")
                return
            for role, spec in zip(("test", "reference"), self.p.response.interval_specs()):
                if value.factor in spec.set:
                    self.add(("response", role, "set", value.factor),
                             f"the rendered NC is the trial's level of '{value.factor}'; an interval cannot override "
                             "it. Remove it from set:")
            values = [condition[value.factor] for condition in conditions]
        else:
            values = [value]
        for level in values:
            try:
                level_f = float(level)
            except (TypeError, ValueError):
                continue
            if math.isnan(level_f):  # adaptive: known at run time; its range is checked below
                a = self.factors[value.factor].adaptive if isinstance(value, FactorRef) else None
                candidates = [float(a.min), float(a.max)] if a is not None else []
            else:
                candidates = [level_f]
            for candidate in candidates:
                nc_m = candidate / 1000.0 if key == "mm" else candidate * eye_nc_m
                if nc.signed and isinstance(value, FactorRef):  # the sign is the mode; 0 renders conventionally
                    nc_m = abs(nc_m) if nc_m != 0.0 else eye_nc_m
                if not NC_M.contains(nc_m):
                    fix = ("a signed level's size must be in that range (its sign picks the mode)" if nc.signed else
                           "for NC 0 render conventionally (mode: conventional), for a reversed NC use mode: reversed")
                    self.add(path, f"{key} {candidate:g} gives a rendered NC of {nc_m * 1000:g} mm, outside "
                                   f"{NC_M.describe(1000, 'mm')}; {fix}")
                    return
        assert rule is not None

    def check_unused_factors(self) -> None:
        used = self.used_factors()
        for name in self.factors:
            if name not in used:
                self.add(("design", "factors", name),
                         f"factor '{name}' is used by nothing: no scene item, response field or other factor refers "
                         "to it, so its conditions would look the same on screen. Refer to it (e.g. depth: "
                         f"{{factor: {name}}}, or a size/contrast field {{factor: {name}}}) or remove it")

    def mode_factor(self, name: str, path: Loc) -> None:
        if self.factor_exists(name, path, numeric=False):
            for level in self.factors[name].all_levels():
                if level not in RENDERING_MODES:
                    self.add(("design", "factors", name, "levels"),
                             f"'{level}' is not a rendering mode.{_suggest(str(level), list(RENDERING_MODES))} "
                             f"Modes: {', '.join(RENDERING_MODES)}")

    def check_validation(self) -> None:
        """``gaze_validation:`` against the design and the ``quality:`` rules (psyop.protocol.validation)."""
        from psyop.protocol.validation import validation_issues

        quality = self.p.quality
        rules: list[tuple[tuple[str | int, ...], str]] = []
        if quality is not None:
            rules += [(("quality", "trials", i, "measure"), rule.measure) for i, rule in enumerate(quality.trials)]
            rules += [(("quality", "participants", i, "measure"), rule.measure)
                      for i, rule in enumerate(quality.participants)]
        for path, message in validation_issues(self.p.gaze_validation, self.p.design.randomisation.kind == "blocked",
                                               rules):
            self.add(path, message)
        self.check_validation_points()

    def check_validation_points(self) -> None:
        """Every validation point inside each seen eye's field of view (at the protocol's ipd, else the
        sessions' default: a tracker's ipd is known only when the session starts)."""
        from psyop.protocol.display import protocol_ipd_m, resolve_display_profile
        from psyop.protocol.validation import points_off_display

        validation = self.p.gaze_validation
        if validation is None:
            return
        try:
            display = resolve_display_profile(self.p.display)
        except (ValueError, KeyError):
            return  # the display's own error is reported where it is checked
        ipd_m = protocol_ipd_m(self.p.display.ipd)
        eyes = ("left", "right") if self.p.eyes == "stereo" else (self.p.eyes,)
        for index, message in points_off_display(validation, display, eyes, ipd_m):
            self.add(("gaze_validation", "points_deg", index), message)

    def check_reported(self) -> None:
        """``study.reported``: a two-interval response's thresholds, each at a condition named by design factors and
        levels they have (the level factor is what the threshold is on, so it names no condition)."""
        response = self.p.response
        for index, reported in enumerate(self.p.study.reported):
            path: Loc = ("study", "reported", index)
            if response.kind != "two_interval":
                self.add(path, f"reported thresholds are compared by the two-interval analysis; this study's response "
                               f"is {response.kind}: remove study.reported")
                return
            for name, level in reported.condition.items():
                where = path + ("condition", name)
                if name == response.level():
                    self.add(where, f"'{name}' is the level factor the threshold is measured on; name the other "
                                    "factors' levels")
                elif self.factor_exists(name, where) and not any(
                        _same(level, have) for have in self.factors[name].all_levels()):
                    self.add(where, f"'{level}' is not a level of {name}")

    def check_session_blocks(self, conditions: list[JsonObject]) -> None:
        """``session: instructions: at_blocks:`` names blocks the design has (run order from 0: one block per
        combination of a blocked design's ``by`` factors, else the one block 0)."""
        screens = self.p.session
        if screens is None or screens.instructions is None or not screens.instructions.at_blocks:
            return
        by = self.p.design.randomisation.by
        n_blocks = len({tuple(str(c.get(f)) for f in by) for c in conditions}) if by else 1
        for index, block in enumerate(screens.instructions.at_blocks):
            if block >= n_blocks:
                self.add(("session", "instructions", "at_blocks", index),
                         f"block {block} does not exist: the design has {n_blocks} block(s), numbered 0 to "
                         f"{n_blocks - 1} in run order; list only those")

    def check_page_images(self) -> None:
        """Every ``session: instructions: pages: image:`` names an image file (relative to the protocol) that
        decodes, as an image surface's path must."""
        screens = self.p.session
        pages = screens.instructions.pages if screens is not None and screens.instructions is not None else []
        base = self.base_dir or FsPath.cwd()
        for index, page in enumerate(pages):
            if page.image is None:
                continue
            where: Loc = ("session", "instructions", "pages", index, "image")
            target = base / page.image
            if not target.is_file():
                self.add(where, f"image file '{page.image}' not found (looked for {target}); paths are relative to "
                                "the protocol file. Fix the path or add the file.")
                continue
            try:
                check_image_file(target, page.image)
            except UserError as error:
                self.add(where, error.message)

    def check_observer(self) -> None:
        observer = self.p.observer
        if observer is None:
            return
        path: Loc = ("observer",)
        response = self.p.response
        kind = kind_of(response)
        accepted = kind.observer_kinds()
        if observer.kind not in accepted:
            self.add(path + ("kind",), f"a {observer.kind} observer cannot answer a {response.kind} response; use "
                                       f"kind: {' or '.join(accepted) if accepted else '(none: this kind has no observer)'}")
            return
        kind.check_observer(observer, response, self, path)


def with_variables(conditions: list[JsonObject], variables: Mapping[str, tuple[float, float]]) -> list[JsonObject]:
    """Each condition with every scene variable (an adjustment's) at each end of its range: the values the scene
    is checked with (none: the conditions themselves)."""
    for name, ends in variables.items():
        conditions = [{**condition, name: float(end)} for condition in conditions for end in ends]
    return conditions


def _in_order(sub: Loc, loc: Loc) -> bool:
    """``sub``'s keys appear in ``loc`` in order (pydantic's loc adds union tags such as 'white_noise')."""
    it = iter(loc)
    return all(any(key == x for x in it) for key in sub)


def _factor_refs(value: object) -> set[str]:
    """Every factor name a scene item refers to (``FactorRef``, ``Depth.factor``), at any depth."""
    if isinstance(value, (FactorRef, LevelRef)):
        return {value.factor}
    if isinstance(value, Depth):
        return set(value.factor_names)
    if isinstance(value, (list, tuple)):
        return set().union(*(_factor_refs(v) for v in value)) if value else set()
    if isinstance(value, dict):
        return set().union(*(_factor_refs(v) for v in value.values())) if value else set()
    if isinstance(value, BaseModel):
        return set().union(set(), *(_factor_refs(getattr(value, n)) for n in type(value).model_fields))
    return set()


def _same(a: float | str, b: float | str) -> bool:
    if isinstance(a, str) or isinstance(b, str):
        return str(a) == str(b)
    return abs(float(a) - float(b)) <= 1e-9 * max(1.0, abs(float(a)))


def check_protocol(protocol: Protocol, base_dir: FsPath | None, meshes: MeshFiles | None = None) -> list[Issue]:
    """Every cross-section problem of a structurally valid protocol (empty list: fine). ``meshes``: the
    command's model cache (psyop.mesh.MeshFiles), so the session reuses the models read here."""
    checker = _Checker(protocol, base_dir, meshes)
    checker.check_factors()
    if checker.issues:
        return checker.issues  # conditions cannot be expanded reliably
    conditions = expand_conditions(protocol.design)
    if len(conditions) * protocol.design.repetitions > 10_000_000:
        checker.add(("design", "repetitions"), f"{len(conditions)} conditions x {protocol.design.repetitions} "
                                               "repetitions is over 10 million trials; reduce them")
    checker.check_scene(with_variables(conditions, checker.variables))
    checker.check_visibility(with_variables(conditions, checker.variables))
    checker.check_primitive_limit()
    checker.check_mesh_budget(conditions)
    checker.check_response()
    checker.check_kind_design()
    checker.check_rendering_nc(conditions)
    checker.check_added_latency(conditions)
    checker.check_luminance(conditions)
    checker.check_unused_factors()
    checker.check_observer()
    checker.check_validation()
    checker.check_session_blocks(conditions)
    checker.check_page_images()
    checker.check_reported()
    return checker.issues
