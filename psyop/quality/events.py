"""Fixations and saccades through pymovements (pinned in pyproject.toml), as its documentation says:
a :class:`pymovements.Gaze` of positions in degrees of visual angle, ``pos2vel``, then ``detect('ivt')``
(fixations) and ``detect('microsaccades')`` (saccades: Engbert & Kliegl's velocity detector, here with an
explicit velocity threshold by default); amplitude and peak velocity are pymovements' own sample
measures (:func:`pymovements.measure.samples.amplitude`, :func:`~pymovements.measure.samples.peak_velocity`)
over each event's samples (``onset <= time <= offset``, as its EventSamplesProcessor selects them).
"""

from __future__ import annotations

import warnings
from dataclasses import asdict, dataclass

import numpy as np
import pandas as pd

EVENT_COLUMNS = ("name", "onset_s", "offset_s", "duration_s", "amplitude_deg", "peak_velocity_deg_s")


@dataclass(frozen=True)
class EventMethod:
    """How events are detected (the protocol's ``quality: events:``; recorded with the results).

    ``velocity_method``: pymovements ``pos2vel`` method (``neighbors``: central difference over two
    samples). Fixations: I-VT below ``fixation_velocity_threshold_deg_s`` for at least
    ``fixation_minimum_duration_s``. Saccades: pymovements ``microsaccades`` with the elliptic threshold
    ``saccade_velocity_threshold_deg_s`` on both axes (``None``: its data-driven ``engbert2015`` threshold
    times ``saccade_threshold_factor``), at least ``saccade_minimum_duration_s``. A saccade smaller than
    ``microsaccade_max_amplitude_deg`` is named ``microsaccade`` when the tracker's rate is at least
    ``microsaccade_min_rate_hz`` (below it, microsaccades are not reported).
    """

    velocity_method: str = "neighbors"
    fixation_velocity_threshold_deg_s: float = 20.0
    fixation_minimum_duration_s: float = 0.1
    saccade_velocity_threshold_deg_s: float | None = 40.0
    saccade_threshold_factor: float = 6.0
    saccade_minimum_duration_s: float = 0.012
    microsaccade_max_amplitude_deg: float = 1.0
    microsaccade_min_rate_hz: float = 250.0

    def record(self, rate_hz: float) -> dict[str, object]:
        """The method and its parameters as recorded with the results."""
        import importlib.metadata

        saccades = (f"explicit elliptic threshold {self.saccade_velocity_threshold_deg_s:g} deg/s"
                    if self.saccade_velocity_threshold_deg_s is not None
                    else f"engbert2015 threshold x {self.saccade_threshold_factor:g}")
        return {"library": f"pymovements {importlib.metadata.version('pymovements')}", **asdict(self),
                "fixations": "pymovements detect('ivt')", "saccades": f"pymovements detect('microsaccades'), {saccades}",
                "microsaccades": "reported" if rate_hz >= self.microsaccade_min_rate_hz
                else f"not reported: {rate_hz:g} Hz is below {self.microsaccade_min_rate_hz:g} Hz"}


def pymovements_gaze(t_s: np.ndarray, az_deg: np.ndarray, el_deg: np.ndarray, rate_hz: float,
                     method: EventMethod):
    """The :class:`pymovements.Gaze` of samples on a regular grid (NaN where there is no valid sample),
    positions in degrees (Fick azimuth, elevation), time in ms, with its velocities (``pos2vel``)."""
    import polars as pl
    import pymovements as pm

    frame = pl.DataFrame({"time": np.asarray(t_s, dtype=np.float64) * 1000.0, "x": np.asarray(az_deg, dtype=np.float64),
                          "y": np.asarray(el_deg, dtype=np.float64)}).with_columns(
        pl.col("x").fill_nan(None), pl.col("y").fill_nan(None))
    gaze = pm.Gaze(frame, experiment=pm.Experiment(sampling_rate=float(rate_hz)), time_column="time", time_unit="ms",
                   position_columns=["x", "y"])
    gaze.pos2vel(method=method.velocity_method)
    return gaze


def detect_events(t_s: np.ndarray, az_deg: np.ndarray, el_deg: np.ndarray, rate_hz: float,
                  method: EventMethod) -> tuple[pd.DataFrame, np.ndarray]:
    """Fixations and saccades of samples on a regular grid (``t_s`` ascending at ``rate_hz``; NaN
    positions where there is no valid sample). Returns the events (:data:`EVENT_COLUMNS`, times in
    s) and the velocities (n, 2) in deg/s that pymovements computed."""
    import polars as pl
    from pymovements.measure.samples import amplitude, peak_velocity

    if len(t_s) < 5:
        return pd.DataFrame({c: pd.Series(dtype="object" if c == "name" else "float64") for c in EVENT_COLUMNS}), \
            np.full((len(t_s), 2), np.nan)
    gaze = pymovements_gaze(t_s, az_deg, el_deg, rate_hz, method)
    ms = 1000.0
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", message=".*No events were detected.*")
        gaze.detect("ivt", velocity_threshold=method.fixation_velocity_threshold_deg_s,
                    minimum_duration=method.fixation_minimum_duration_s * ms, name="fixation")
        threshold = (("engbert2015", {"threshold_factor": method.saccade_threshold_factor})
                     if method.saccade_velocity_threshold_deg_s is None
                     else ((method.saccade_velocity_threshold_deg_s,) * 2, {"threshold_factor": 1.0}))  # radius = threshold x factor
        try:
            gaze.detect("microsaccades", threshold=threshold[0], minimum_duration=method.saccade_minimum_duration_s * ms,
                        name="saccade", **threshold[1])
        except ValueError as exc:  # engbert2015 on data without velocity spread (too few samples)
            if "threshold" not in str(exc):
                raise
    events = gaze.events.frame.select("name", "onset", "offset").sort("onset")
    samples = gaze.samples.select("time", "position", "velocity")
    velocity = samples["velocity"].list.to_array(2).to_numpy().astype(np.float64).reshape(-1, 2)
    if events.height == 0:
        return detect_events(t_s[:0], az_deg[:0], el_deg[:0], rate_hz, method)[0], velocity
    rows = []
    for name in events["name"].unique(maintain_order=True).to_list():
        of_name = events.filter(pl.col("name") == name).with_row_index("event")
        onsets = of_name["onset"].to_numpy()
        offsets = of_name["offset"].to_numpy()
        time = samples["time"].to_numpy()
        index = np.searchsorted(onsets, time, side="right") - 1
        inside = (index >= 0) & (time <= offsets[np.clip(index, 0, None)])
        members = samples.with_columns(pl.Series("event", np.where(inside, index, -1), dtype=pl.UInt32,
                                                 strict=False)).filter(pl.Series(inside))
        props = members.group_by("event").agg(amplitude(position_column="position"),
                                              peak_velocity(velocity_column="velocity"))
        rows.append(of_name.join(props, on="event", how="left").drop("event"))
    frame = pl.concat(rows).sort("onset").to_pandas()
    out = pd.DataFrame({"name": frame["name"].astype(str), "onset_s": frame["onset"] / ms, "offset_s": frame["offset"] / ms})
    out["duration_s"] = out["offset_s"] - out["onset_s"]
    out["amplitude_deg"] = frame["amplitude"].astype("float64")
    out["peak_velocity_deg_s"] = frame["peak_velocity"].astype("float64")
    if rate_hz >= method.microsaccade_min_rate_hz:
        out.loc[(out["name"] == "saccade") & (out["amplitude_deg"] < method.microsaccade_max_amplitude_deg),
                "name"] = "microsaccade"
    return out.reset_index(drop=True), velocity
