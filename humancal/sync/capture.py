"""A capture's views put on one clock: the time offsets given or estimated, checked, and applied to its detections
(what :func:`humancal.captures.load_capture` does for a capture declared unsynchronised)."""

from __future__ import annotations

import logging
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np
import pandas as pd

from humancal.sync.apply import apply_time_offsets
from humancal.sync.offsets import SyncConfig, TimeOffsets, estimate_time_offsets, tentative_offsets_s
from humancal.sync.periods import PeriodSearch, misplaced_period_s, regroup_by_period
from humancal.sync.with_cameras import CameraCheck, check_offsets_with_cameras

__all__ = ["DEFAULT_SYNC_FPS", "CaptureSync", "OffsetCheck", "calibrate_and_check", "check_and_regroup",
           "synchronise_views"]

log = logging.getLogger(__name__)

DEFAULT_SYNC_FPS = 30.0
"""The frame rate assumed for a view whose rate the capture does not state
(``humancal.datasets.inputs.DEFAULT_FPS``)."""


@dataclass(frozen=True)
class CaptureSync:
    """How a capture's views were put on view 0's clock.

    Attributes:
        source: ``"estimated"`` (from the people's motion, now), ``"estimated by humancal add"`` (stored then) or
            ``"given"``.
        fps: (V,) frames per second of each view.
        offset_s: (V,) time offsets, seconds (view 0: 0).
        offset_frames: (V,) the same in reference frames.
        status: (V,) ``"ok"`` (estimated and cross-checked: by a cycle of pairs of views, or by the cameras
            calibrated from the people) or ``"given"`` (an unchecked or ambiguous estimate is refused, never stored).
        confidence: (V,) the estimate's margin (NaN where given).
        residual_frames: (V,) the largest sub-frame remainder of a detection taken from its nearest frame, reference
            frames (0 where every detection was interpolated).
        dropped_frames: (V,) frames with detections dropped (outside view 0's frames, or merged).
        reference_fps: the reference clock's frames per second (view 0's, before any view was left out).
        camera_check: (V,) what the check against cameras calibrated from the people did to each estimated offset
            (:func:`humancal.sync.check_offsets_with_cameras`: ``"agrees"``, ``"agrees (+0.21 frame)"``,
            ``"moved +1.30 frames"``, ``"flat"``),
            or why it did not run; empty where the offsets were given.
        interpolated: (V,) detections blended between two of the view's frames at view 0's frame times
            (:func:`humancal.sync.apply_time_offsets` with ``interpolate``); empty where the nearest frames were taken.
    """

    source: str
    fps: tuple[float, ...]
    offset_s: tuple[float, ...]
    offset_frames: tuple[float, ...]
    status: tuple[str, ...]
    confidence: tuple[float, ...]
    residual_frames: tuple[float, ...]
    dropped_frames: tuple[int, ...]
    reference_fps: float = DEFAULT_SYNC_FPS
    camera_check: tuple[str, ...] = ()
    interpolated: tuple[int, ...] = ()

    def pick(self, views: Sequence[int]) -> CaptureSync:
        """The same for the views ``views`` only (after some were left out)."""
        def sub(values: tuple) -> tuple:
            return tuple(values[v] for v in views)

        return CaptureSync(self.source, sub(self.fps), sub(self.offset_s), sub(self.offset_frames), sub(self.status),
                           sub(self.confidence), sub(self.residual_frames), sub(self.dropped_frames),
                           self.reference_fps, sub(self.camera_check) if self.camera_check else (),
                           sub(self.interpolated) if self.interpolated else ())

    def view_text(self, v: int) -> str:
        """View ``v``'s offset in words, for the capture summary."""
        text = f"time offset {self.offset_s[v]:+.3f} s ({self.offset_frames[v]:+.2f} frames at {self.reference_fps:g} fps"
        if self.status[v] != "given":
            text += f", {self.status[v]}, confidence {self.confidence[v]:.2f}"
            if self.camera_check:
                text += f", cameras: {self.camera_check[v]}"
        text += ")"
        if self.fps[v] != self.reference_fps:
            text += f", {self.fps[v]:g} fps"
        if self.interpolated and self.interpolated[v]:
            text += f", {self.interpolated[v]} detections interpolated between frames"
        if self.residual_frames[v] > 1e-6:
            text += f", up to {self.residual_frames[v]:.2f} frame rounded"
        if self.dropped_frames[v]:
            text += f", {self.dropped_frames[v]} frames outside view 0's dropped"
        return text

    def metadata(self, names: Sequence[str]) -> dict[str, str]:
        """The offsets as text, for an asset's metadata (view names as keys)."""
        return {"time_offsets_source": self.source,
                **{f"time_offset_{name}": self.view_text(v) for v, name in enumerate(names)}}


def _per_view(names: Sequence[str], default: float, named: Sequence[tuple[str, float]], option: str) -> np.ndarray:
    known = dict(named)
    unknown = sorted(set(known) - set(names))
    if unknown:
        raise ValueError(f"{option}: {unknown} are not views of the capture (its views: {list(names)})")
    return np.array([known.get(n, default) for n in names], dtype=float)


def synchronise_views(detections: pd.DataFrame, names: Sequence[str], *, fps: float | None,
                      view_fps: Sequence[tuple[str, float]], unsynced: bool,
                      time_offsets_s: Sequence[tuple[str, float]], option_names: Mapping[str, str],
                      lifter_factory=None, config: SyncConfig = SyncConfig(),
                      image_sizes_px: Sequence[tuple[int, int]] | None = None, interpolate: bool = True
                      ) -> tuple[pd.DataFrame, CaptureSync]:
    """Move a capture's detections to view 0's frames.

    The offsets are ``time_offsets_s`` where given (``unsynced`` then says they were estimated by ``humancal add``),
    else estimated (``unsynced``), else 0 (only the frame rates differ). Estimated offsets are then checked against
    cameras calibrated from the people on the synchronised detections when ``image_sizes_px`` is given
    (:func:`check_offsets_with_cameras`): a view they put a whole frame or more off is moved there, a view whose
    people they cannot place at any shift is refused.

    Args:
        detections: canonical ``detections`` table, each view on its own frames.
        names: (V,) view names.
        fps: the frame rate of the views ``view_fps`` does not name (None: :data:`DEFAULT_SYNC_FPS`).
        view_fps: (name, frames per second) per view.
        unsynced: whether the views were started by hand.
        time_offsets_s: (name, seconds) per view (views not named: 0).
        option_names: how messages name the options (keys ``fps``, ``view_fps``, ``unsynced``, ``time_offsets``).
        lifter_factory: returns the :class:`humancal.lifter.Lifter` the estimate uses (default: the shipped one).
        config: the search.
        image_sizes_px: (V,) ``(width, height)`` of each view's images: estimated offsets are checked against
            cameras calibrated from the people (None: not checked).
        interpolate: each view's people at view 0's frame times, blended between the view's two frames around each
            (a detection whose track has no frame on the other side: its nearest frame); False: the nearest frames.

    Returns:
        ``(detections on view 0's frames, how)``.

    Raises:
        ValueError: a name that is no view, or an estimated offset that is ambiguous, unchecked or disagrees with
            the calibrated cameras (the message names the view and how to give its offset).
    """
    rates = _per_view(names, DEFAULT_SYNC_FPS if fps is None else float(fps), view_fps, option_names["view_fps"])
    V = len(names)
    camera_check: tuple[str, ...] = ()
    if time_offsets_s:
        offsets = _per_view(names, 0.0, time_offsets_s, option_names["time_offsets"])
        source = "estimated by humancal add" if unsynced else "given"
        status = ("given",) * V
        confidence = np.full(V, np.nan)
    elif unsynced:
        if lifter_factory is None:
            from humancal.lifter import load_lifter, shipped_checkpoint

            def lifter_factory():
                return load_lifter(shipped_checkpoint())

        lifter = lifter_factory()
        estimate = estimate_time_offsets(detections, rates, lifter=lifter, config=config)
        unchecked = [v for v, s in enumerate(estimate.status) if s == "unchecked"]
        # with cameras to check them, unchecked offsets and tentative ones for ambiguous views get their chance: the
        # cameras may confirm them
        offsets = estimate.offset_s if image_sizes_px is None else tentative_offsets_s(estimate)
        tentative = [v for v in estimate.ambiguous_views() if np.isfinite(offsets[v])]
        _refuse_unusable(estimate, names, option_names, config, [] if image_sizes_px is not None else unchecked,
                         ambiguous=sorted(set(estimate.ambiguous_views()) - set(tentative)))
        source, status, confidence = "estimated", estimate.status, estimate.confidence
        if image_sizes_px is not None:
            offsets, camera_check, check = _checked_with_cameras(detections, offsets, rates, names, image_sizes_px,
                                                                 lifter, option_names, interpolate,
                                                                 misplaced_period_s(estimate, offsets))
            confirmed = [v for v in unchecked + tentative if check is not None and check.confirms(v)]
            _refuse_unusable(estimate, names, option_names, config, sorted(set(unchecked) - set(confirmed)),
                             ambiguous=sorted(set(tentative) - set(confirmed)), cameras_tried=True)
            status = tuple("ok" if v in confirmed else st for v, st in enumerate(status))
            camera_check = tuple(
                c + (" (confirms an offset one pair of views gave)" if v in confirmed and v in unchecked
                     else " (confirms the offset of a view the motion left ambiguous)" if v in confirmed else "")
                for v, c in enumerate(camera_check))
    else:
        offsets = np.zeros(V)
        source, status, confidence = "given", ("given",) * V, np.full(V, np.nan)
    applied = apply_time_offsets(detections, offsets, rates, interpolate=interpolate)
    sync = CaptureSync(source, tuple(map(float, rates)), tuple(map(float, offsets)),
                       tuple(float(o * rates[0]) for o in offsets), tuple(status), tuple(map(float, confidence)),
                       tuple(map(float, applied.residual_frames)), tuple(map(int, applied.dropped_frames)),
                       float(rates[0]), camera_check, tuple(map(int, applied.interpolated)) if interpolate else ())
    for v, name in enumerate(names):
        log.info("view %d (%s): %s", v, name, sync.view_text(v))
    return applied.detections, sync


def calibrate_and_check(detections: pd.DataFrame, offsets_s: np.ndarray, rates: np.ndarray,
                        image_sizes_px: Sequence[tuple[int, int]], lifter,
                        view_names: Sequence[str] | None = None, interpolate: bool = True) -> CameraCheck:
    """The views put on one clock with ``offsets_s``, their cameras calibrated from the people as the graph does
    (:func:`humancal.calibration.estimate_intrinsics`, :func:`~humancal.calibration.estimate_extrinsics`), and each
    offset checked with them (:func:`check_offsets_with_cameras`, a camera the calibration judges disagreeing
    vouching for nothing).

    Args:
        detections: canonical ``detections`` table, each view on its own frames (views ``0 .. V-1``).
        offsets_s: (V,) the offsets to check, seconds.
        rates: (V,) frames per second of each view.
        image_sizes_px: (V,) ``(width, height)`` of each view's images.
        lifter: the :class:`humancal.lifter.Lifter` whose poses the calibration uses.
        view_names: (V,) names for the calibration's messages.
        interpolate: each view's people blended at view 0's frame times (as the capture will be, so that a view
            filming at another rate moves smoothly with each shift the check tries); False: their nearest frames.

    Raises:
        CalibrationError: the calibration failed.
    """
    from humancal.calibration import IntrinsicsConfig, estimate_extrinsics, estimate_intrinsics
    from humancal.lifter import lift_detections
    from humancal.tables.detections import detections_to_dense

    dense = detections_to_dense(apply_time_offsets(detections, offsets_s, rates, interpolate=interpolate).detections)
    lifted = lift_detections(lifter, dense.keypoints_px, dense.scores)
    intrinsics = estimate_intrinsics(dense, lifted, list(image_sizes_px), IntrinsicsConfig(missing_upright="defer"))
    calibrated = estimate_extrinsics(dense, lifted, intrinsics,
                                     view_names=None if view_names is None else list(view_names))
    return check_offsets_with_cameras(dense, calibrated.cameras,
                                      camera_verdicts=calibrated.diagnostics.per_view["agreement"].tolist())


@dataclass(frozen=True)
class OffsetCheck:
    """What :func:`check_and_regroup` did.

    Attributes:
        offset_s: (V,) the offsets the check judged, seconds: as given, or moved by whole periods of the people's
            motion (``regrouped``).
        check: the check of those offsets against cameras calibrated on them.
        period_search: the search for views placed a period off (:func:`humancal.sync.periods.regroup_by_period`;
            None: it did not run, no view disagreeing or no period to search).
        regrouped: whether the offsets it moved were checked and kept (fewer views disagree than before).
        first_check: the check of the offsets as given, when they were regrouped (None otherwise).
    """

    offset_s: np.ndarray
    check: CameraCheck
    period_search: PeriodSearch | None = None
    regrouped: bool = False
    first_check: CameraCheck | None = None


def check_and_regroup(detections: pd.DataFrame, offsets_s: np.ndarray, rates: np.ndarray,
                      image_sizes_px: Sequence[tuple[int, int]], lifter, period_s: float | None,
                      view_names: Sequence[str] | None = None, interpolate: bool = True) -> OffsetCheck:
    """:func:`calibrate_and_check`; where views disagree with the cameras and some pairs of views disagree with the
    offsets by about a period of the people's motion (``period_s``, :func:`humancal.sync.misplaced_period_s`), the
    views are moved by whole periods where the pairs' epipolar geometry supports them best
    (:func:`humancal.sync.periods.regroup_by_period`: a group of views a gait cycle off together) and checked again
    on cameras calibrated on the new clock; the new offsets are kept when fewer views disagree.

    Args:
        detections, offsets_s, rates, image_sizes_px, lifter, view_names, interpolate: as :func:`calibrate_and_check`.
        period_s: the period to search, seconds (None: no search).

    Raises:
        CalibrationError: the first calibration failed (a failure of the second keeps the first check).
    """
    from humancal.calibration import CalibrationError

    check = calibrate_and_check(detections, offsets_s, rates, image_sizes_px, lifter, view_names, interpolate)
    disagreeing = check.status.count("disagrees")
    if period_s is None or not disagreeing:
        return OffsetCheck(offsets_s, check)
    log.info("%d views disagree with the cameras; searching for views placed %.2f s (a period of the people's "
             "motion) off ...", disagreeing, period_s)
    search = regroup_by_period(detections, offsets_s, rates, period_s)
    if not search.moved:
        log.info("no group of views is better supported a period away")
        return OffsetCheck(offsets_s, check, search)
    log.info("views %s moved by %s periods; checking them against cameras calibrated on that clock ...",
             search.moved, search.shift_periods[search.moved].tolist())
    try:
        second = calibrate_and_check(detections, search.offset_s, rates, image_sizes_px, lifter, view_names,
                                     interpolate)
    except CalibrationError as error:
        log.warning("the calibration on the regrouped offsets failed (%s): the first check stands", error)
        return OffsetCheck(offsets_s, check, search)
    if second.status.count("disagrees") >= disagreeing:
        log.info("the regrouped offsets do no better (%d views disagree): the first check stands",
                 second.status.count("disagrees"))
        return OffsetCheck(offsets_s, check, search)
    return OffsetCheck(search.offset_s, second, search, regrouped=True, first_check=check)


def _checked_with_cameras(detections: pd.DataFrame, offsets_s: np.ndarray, rates: np.ndarray, names: Sequence[str],
                          image_sizes_px: Sequence[tuple[int, int]], lifter, option_names: Mapping[str, str],
                          interpolate: bool = True, period_s: float | None = None
                          ) -> tuple[np.ndarray, tuple[str, ...], CameraCheck | None]:
    """The estimated offsets after :func:`check_and_regroup`, what it did per view (the words of
    :attr:`CaptureSync.camera_check`) and the check (None: the calibration failed).

    Raises:
        ValueError: a view the cameras disagree with (named, with how to give its offset).
    """
    from humancal.calibration import CalibrationError

    log.info("checking the time offsets against cameras calibrated from the people ...")
    try:
        checked = check_and_regroup(detections, offsets_s, rates, image_sizes_px, lifter, period_s, names,
                                    interpolate)
    except CalibrationError as error:
        log.warning("the time offsets were not checked against cameras: the calibration failed (%s)", error)
        return offsets_s, (f"not checked ({type(error).__name__})",) * len(names), None
    check, offsets_s = checked.check, checked.offset_s
    _refuse_disagreeing(check, offsets_s, names, option_names, float(rates[0]))
    words = tuple(_check_words(check, v, checked) for v in range(len(names)))
    return check.corrected_offsets_s(offsets_s, rates[0]), words, check


def _check_words(check: CameraCheck, v: int, checked: OffsetCheck | None = None) -> str:
    move = -float(check.shift[v])
    if check.status[v] == "moved":
        words = f"moved {move:+.2f} frames"
    else:
        words = check.status[v] + (f" ({move:+.2f} frame)" if round(move, 2) else "")
    if checked is not None and checked.regrouped and checked.period_search.shift_periods[v]:
        search = checked.period_search
        words += (f", after a move of {search.shift_periods[v] * search.period_s:+.3f} s (a period of the people's "
                  f"motion) that the pairs of views' epipolar geometry supports")
    return words


def _refuse_disagreeing(check: CameraCheck, offsets_s: np.ndarray, names: Sequence[str],
                        option_names: Mapping[str, str], reference_fps: float) -> None:
    """Raise naming every view whose people the calibrated cameras cannot place at any shift searched, and every
    view the two halves of the capture place apart (``"unsure"``)."""
    bad = [v for v, s in enumerate(check.status) if s == "disagrees"]
    unsure = [v for v, s in enumerate(check.status) if s == "unsure"]
    if not (bad or unsure):
        return
    option = option_names["time_offsets"]
    parts = []
    if bad:
        views, example = _named(bad, names, offsets_s), _flag_values(bad, names)
        parts.append(
            f"{views}: the time offset estimated from the people's motion disagrees with the cameras calibrated from "
            f"them on that clock: the calibration judged the camera disagreeing with the others, or its people miss "
            f"the other views' ({', '.join(f'{check.level_m[v]:.2f}' for v in bad)} m, the others "
            f"{np.nanmedian(check.level_m):.2f} m) at every shift of up to {(check.cost_m.shape[1] - 1) // 2} "
            f"frames. The motion matched a wrong moment (a walk repeats every second or so). Give the offsets you "
            f"know ({option} {example}), or leave the view out")
    if unsure:
        corrected = check.corrected_offsets_s(offsets_s, reference_fps)
        views, example = _named(unsure, names, corrected), _flag_values(unsure, names)
        apart = ", ".join("not compared in one half" if not np.isfinite(check.spread_frames[v])
                          else f"{check.spread_frames[v]:.1f}" for v in unsure)
        parts.append(
            f"{views}: the cameras calibrated from the people cannot fix the time offset to the frame: the first "
            f"and the second half of the capture place the view {apart} frames apart (people who move slowly, "
            f"like seated people). Give the offsets you know ({option} {example}: a clap, a flash, the files' "
            f"timestamps), or film people walking where the cameras see them")
    raise ValueError(". ".join(parts))


def _named(views: Sequence[int], names: Sequence[str], offsets_s: np.ndarray | None = None) -> str:
    """``view 2 (right, -0.997 s?), ...``: the views as messages name them, with the offset in doubt."""
    return ", ".join(f"view {v} ({names[v]}" + ("" if offsets_s is None else f", {offsets_s[v]:+.3f} s?") + ")"
                     for v in views)


def _flag_values(views: Sequence[int], names: Sequence[str]) -> str:
    """``right=SECONDS ...``: the values of the time-offsets option for the views."""
    return " ".join(f"{names[v]}=SECONDS" for v in views)


def _refuse_unusable(estimate: TimeOffsets, names: Sequence[str], option_names: Mapping[str, str],
                     config: SyncConfig, unchecked: Sequence[int], ambiguous: Sequence[int] | None = None,
                     cameras_tried: bool = False) -> None:
    """Raise naming every view whose estimated offset is not cross-checked: among ``ambiguous`` (default: the
    estimate's), no clear peak, or among ``unchecked``, one pair of views alone places it; and nothing confirms it
    (on the synthetic sweep such views were the ones used one or more frames off); ``cameras_tried``: the calibrated
    cameras did not confirm them either (for an ambiguous view: its tentative offset)."""
    ambiguous = estimate.ambiguous_views() if ambiguous is None else list(ambiguous)
    if not (ambiguous or unchecked):
        return
    option = option_names["time_offsets"]
    parts = []
    if ambiguous:
        views, example = _named(ambiguous, names), _flag_values(ambiguous, names)
        parts.append(
            f"{views}: the time offset is ambiguous: the people's motion gives no clear peak within "
            f"+-{config.max_offset_s:g} s of view 0 ({names[0]}) (people who hardly move, or a motion that repeats, "
            f"like a steady walk)"
            f"{'; the cameras calibrated from the people did not confirm a tentative offset' if cameras_tried else ''}"
            f". Film people moving (walking, stopping, turning, waving) in the shared field of view for longer, or "
            f"give the offsets ({option} {example})")
    if unchecked:
        views, example = _named(unchecked, names, estimate.offset_s), _flag_values(unchecked, names)
        parts.append(
            f"{views}: the time offset rests on one pair of views only, no other pair "
            f"{'nor the cameras calibrated from the people ' if cameras_tried else ''}confirms it, so it is not "
            f"used. Check the offset shown (a clap, a flash, the files' timestamps) and give it ({option} "
            f"{example}), or film people moving where more cameras see them")
    raise ValueError(". ".join(parts))
