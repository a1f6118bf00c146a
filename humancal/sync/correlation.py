"""Cross-correlation of two views' tracked people over time lags: where the best lag is, how high, and how clearly
it stands above the next best one.

No one knows which track of one view is which of the other, so at every lag each track picks its best partner:

1. the tracks' signals are put on a common clock (:func:`resample_tracks`);
2. for every pair of tracks (one per view) and every lag, the Pearson correlation of each channel over the samples
   both tracks know at that lag (masked normalised cross-correlation: the sums over the overlap are
   cross-correlations of the signals, their squares and their weights, computed for all pairs at once by FFT),
   averaged over the channels; a pair sharing fewer than ``min_overlap`` samples at a lag says nothing there;
3. the view pair's score at a lag: each track's best partner's correlation, averaged over the tracks of both views,
   weighted by the samples shared, times the square root of the samples shared relative to the best lag's. At the true lag the same person's curves line up and the score peaks; at any
   other lag a track's best partner is a chance match.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.fft import irfft, next_fast_len, rfft

from humancal.sync.signals import TrackSignals

__all__ = ["ClockTracks", "LagPeak", "resample_tracks", "correlate_views", "find_peak", "pose_distance"]

_MAX_PRODUCT = 4_000_000
"""Largest number of (track, track, frequency) products computed at once (memory on long captures)."""


@dataclass(frozen=True)
class ClockTracks:
    """A view's tracks on the common clock.

    Attributes:
        start: the common-clock sample of column 0 (sample ``k`` is at the view's own time ``k / rate_hz`` s).
        values: (T, N, C) per track, sample and channel.
        weight: (T, N, C) 1 where known, 0 where not.
        rate_hz: samples per second of the common clock.
        pose_m: (T, N, P) distances between every two joints of the lifted pose, metres (NaN where unknown), or
            None (:class:`humancal.sync.signals.TrackSignals`).
    """

    start: int
    values: np.ndarray
    weight: np.ndarray
    rate_hz: float
    pose_m: np.ndarray | None = None


@dataclass(frozen=True)
class LagPeak:
    """The best lag of a score curve.

    Attributes:
        lag: the refined lag, common-clock samples (the integer peak moved by a parabola through its neighbours,
            at most half a sample).
        lag_int: the integer lag of the peak, samples.
        peak: the score there, in [-1, 1].
        second: the highest other local maximum more than ``exclusion`` samples from the peak, or the score at the
            window's edge if higher (-1 when none).
        margin: ``peak - second``: how clearly the peak stands out (about 0: two equal peaks, or a flat curve).
    """

    lag: float
    lag_int: int
    peak: float
    second: float
    margin: float


def resample_tracks(tracks: TrackSignals, fps: float, rate_hz: float) -> ClockTracks:
    """A view's tracks on a common clock of ``rate_hz`` samples per second (linear interpolation between the two
    frames around each sample, known where both are; the same samples when ``fps == rate_hz``).

    Args:
        tracks: the view's tracks on its own frames.
        fps: the view's frames per second.
        rate_hz: the common clock's samples per second.
    """
    if fps == rate_hz:
        return ClockTracks(tracks.first_frame, tracks.values, tracks.weight, rate_hz, tracks.pose_m)
    F = tracks.values.shape[1]
    t0, t1 = tracks.first_frame / fps, (tracks.first_frame + F - 1) / fps
    k = np.arange(int(np.ceil(t0 * rate_hz - 1e-9)), int(np.floor(t1 * rate_hz + 1e-9)) + 1)
    pos = k / rate_hz * fps - tracks.first_frame  # fractional frame of each sample
    lo = np.clip(np.floor(pos + 1e-9).astype(int), 0, F - 1)
    hi = np.clip(lo + 1, 0, F - 1)
    frac = np.clip(pos - lo, 0.0, 1.0)[None, :, None]
    values = (1 - frac) * tracks.values[:, lo] + frac * tracks.values[:, hi]
    exact = frac < 1e-9
    weight = np.where(exact, tracks.weight[:, lo], tracks.weight[:, lo] * tracks.weight[:, hi])
    pose = None
    if tracks.pose_m is not None:  # NaN unless both frames around the sample are known (or it falls on one)
        pose = np.where(exact, tracks.pose_m[:, lo], (1 - frac) * tracks.pose_m[:, lo] + frac * tracks.pose_m[:, hi])
    return ClockTracks(int(k[0]) if len(k) else 0, values, weight, rate_hz, pose)


def correlate_views(a: ClockTracks, b: ClockTracks, max_lag: int, min_overlap: int) -> tuple[np.ndarray, np.ndarray]:
    """The score of two views' tracks at each lag (module docstring).

    The lag ``D`` says ``b``'s sample ``k`` shows what ``a``'s sample ``k + D`` shows: with the offsets of
    :func:`humancal.sync.estimate_time_offsets`, ``D = (offset_b - offset_a) * rate_hz``.

    Args:
        a, b: the two views' tracks on one clock.
        max_lag: lags ``-max_lag .. max_lag`` are evaluated, samples.
        min_overlap: a track pair sharing fewer samples at a lag is not compared there.

    Returns:
        ``(lags, score)``: (L,) int lags and (L,) scores (NaN where no track pair shares ``min_overlap`` samples).
    """
    Ta, Na, C = a.values.shape
    Tb, Nb, _ = b.values.shape
    lags = np.arange(-max_lag, max_lag + 1)
    # lag D of the clock is lag l = D + b.start - a.start of the arrays: sum_n a[n + l] b[n]
    shift = lags + b.start - a.start
    inside = (shift > -Nb) & (shift < Na)
    if not (Ta and Tb and inside.any()):
        return lags, np.full(len(lags), np.nan)
    nfft = next_fast_len(Na + Nb - 1, real=True)
    index = np.mod(shift[inside], nfft)
    # in chunks of a's tracks, so that the (tracks, tracks, nfft) products stay small on long captures
    chunk = max(1, int(_MAX_PRODUCT // max(Tb * nfft, 1)))
    parts = [_pair_correlations(a.values[i:i + chunk], a.weight[i:i + chunk], b.values, b.weight, nfft, index,
                                min_overlap) for i in range(0, Ta, chunk)]
    pair = np.concatenate([p for p, _ in parts])
    shared = np.concatenate([s for _, s in parts])
    weight = np.where(np.isfinite(pair), shared, 0.0)
    score_sum = np.zeros(pair.shape[-1])
    weight_sum = np.zeros(pair.shape[-1])
    for axis in (1, 0):  # each track of a picks its best partner in b, then each track of b in a
        best = np.argmax(pair, axis=axis)
        r = np.take_along_axis(pair, np.expand_dims(best, axis), axis).squeeze(axis)
        w = np.take_along_axis(weight, np.expand_dims(best, axis), axis).squeeze(axis)
        score_sum += np.where(np.isfinite(r), r, 0.0).__mul__(w).sum(axis=0)
        weight_sum += w.sum(axis=0)
    score = np.full(len(lags), np.nan)
    with np.errstate(invalid="ignore", divide="ignore"):
        score[inside] = np.where(weight_sum > 0, score_sum / weight_sum, np.nan)
        # a lag where the tracks share little correlates well by chance (a walk's stride repeats every second):
        # the score is discounted by the square root of the overlap's share of the largest one
        score[inside] *= np.sqrt(weight_sum / max(weight_sum.max(), 1.0))
    return lags, score


def _pair_correlations(va: np.ndarray, wa_all: np.ndarray, vb: np.ndarray, wb_all: np.ndarray, nfft: int,
                       index: np.ndarray, min_overlap: int) -> tuple[np.ndarray, np.ndarray]:
    """(Ta, Tb, L) channel-averaged correlation of every track pair at the lags ``index`` of a circular correlation
    of length ``nfft`` (-inf where undefined), and (Ta, Tb, L) the samples each pair shares there."""

    def spectra(x: np.ndarray) -> np.ndarray:
        return rfft(x, nfft, axis=1)

    def xc(fa: np.ndarray, fb: np.ndarray) -> np.ndarray:
        return irfft(fa[:, None] * np.conj(fb[None]), nfft, axis=-1)[..., index]

    shared = np.rint(xc(spectra(wa_all.max(axis=2)), spectra(wb_all.max(axis=2))))
    total = np.zeros(shared.shape)
    used = np.zeros(shared.shape)
    for c in range(va.shape[2]):
        wa, wb = wa_all[..., c], wb_all[..., c]
        x, y = va[..., c] * wa, vb[..., c] * wb
        Fwa, Fwb, Fx, Fy = spectra(wa), spectra(wb), spectra(x), spectra(y)
        n = np.rint(xc(Fwa, Fwb))
        sx, sy = xc(Fx, Fwb), xc(Fwa, Fy)
        sxx, syy = xc(spectra(x * x), Fwb), xc(Fwa, spectra(y * y))
        sxy = xc(Fx, Fy)
        with np.errstate(invalid="ignore", divide="ignore"):
            vx = sxx - sx * sx / n
            vy = syy - sy * sy / n
            r = (sxy - sx * sy / n) / np.sqrt(vx * vy)
            # a channel flat over the overlap (a joint that does not move) says nothing there
            ok = (n >= min_overlap) & (vx > 1e-9 * np.abs(sxx) + 1e-12) & (vy > 1e-9 * np.abs(syy) + 1e-12)
        total += np.where(ok, np.clip(r, -1.0, 1.0), 0.0)
        used += ok
    with np.errstate(invalid="ignore", divide="ignore"):
        pair = np.where((used > 0) & (shared >= min_overlap), total / used, -np.inf)
    return pair, shared


def find_peak(lags: np.ndarray, score: np.ndarray, exclusion: int) -> LagPeak | None:
    """The highest score, refined to a fraction of a sample, and the best other local maximum.

    Args:
        lags, score: from :func:`correlate_views`.
        exclusion: local maxima within this many samples of the peak belong to it (its own shoulders).

    Returns:
        The :class:`LagPeak`, or None where the score is undefined at every lag.
    """
    finite = np.isfinite(score)
    if not finite.any():
        return None
    r = np.where(finite, score, -np.inf)
    i = int(np.argmax(r))
    peak = float(r[i])
    delta = 0.0
    if 0 < i < len(r) - 1 and np.isfinite(r[i - 1]) and np.isfinite(r[i + 1]):
        curvature = r[i - 1] - 2 * r[i] + r[i + 1]
        if curvature < 0:
            delta = float(np.clip(0.5 * (r[i - 1] - r[i + 1]) / curvature, -0.5, 0.5))
    left = np.r_[-np.inf, r[:-1]]
    right = np.r_[r[1:], -np.inf]
    far = finite & (np.abs(lags - lags[i]) > exclusion)
    local = far & (r >= left) & (r >= right)
    candidates = list(r[local])
    if far.any():  # a curve still rising at the window's edge has its best other value there
        edges = np.flatnonzero(far)
        candidates += [r[edges[0]], r[edges[-1]]]
    second = float(max(candidates)) if candidates else -1.0
    return LagPeak(float(lags[i] + delta), int(lags[i]), peak, second, peak - second)


def pose_distance(a: ClockTracks, b: ClockTracks, lags: np.ndarray, min_overlap: int) -> np.ndarray:
    """How far apart the same people's lifted poses are at each of a few integer lags: the sharper criterion that
    picks a pair's integer lag near the correlation's peak.

    The correlation of smoothed joint angles peaks broadly (its neighbours within a frame or two score almost as
    high); the poses themselves tell the lags apart better: at the right lag a person's pose in one view is the
    same instant's pose in the other, one frame off it is moved by a frame's motion. Per track pair and lag, the
    mean over the shared samples of the mean absolute difference of the distances between every two joints (which
    do not depend on the frame the lifter expressed the pose in); each track takes its nearest partner in the
    other view (both directions), weighted by the samples shared. On 234 pairs of views of 20 synthetic scenes
    with the correlation's peak within 3 frames of the truth, this picks the true lag for 72 % against 62 % for the
    correlation's own integer peak.

    Args:
        a, b: the two views' tracks on one clock, with ``pose_m``.
        lags: (L,) integer lags ``D`` as in :func:`correlate_views` (``b``'s sample ``k`` is ``a``'s ``k + D``).
        min_overlap: a track pair sharing fewer samples at a lag is not compared there.

    Returns:
        (L,) mean pose difference, metres (NaN at a lag where no track pair shares ``min_overlap`` samples).

    Raises:
        ValueError: a view without lifted poses.
    """
    if a.pose_m is None or b.pose_m is None:
        raise ValueError("pose_distance needs the lifted poses (pose_m) of both views")
    Ta, Na, _ = a.pose_m.shape
    Tb, Nb, _ = b.pose_m.shape
    out = np.full(len(lags), np.nan)
    for index, lag in enumerate(np.asarray(lags, dtype=int)):
        shift = int(lag) + b.start - a.start  # b's array index j is a's j + shift
        j0, j1 = max(0, -shift), min(Nb, Na - shift)
        if j1 - j0 < min_overlap or not (Ta and Tb):
            continue
        mean = np.full((Ta, Tb), np.inf)
        shared = np.zeros((Ta, Tb))
        for i in range(Ta):
            # (Tb, M): per pair of tracks and shared sample, the mean |difference| over the joint pairs
            diff = np.abs(a.pose_m[i, j0 + shift:j1 + shift][None] - b.pose_m[:, j0:j1]).mean(axis=-1)
            known = np.isfinite(diff)
            shared[i] = known.sum(axis=1)
            with np.errstate(invalid="ignore", divide="ignore"):
                mean[i] = np.where(shared[i] >= min_overlap, np.where(known, diff, 0.0).sum(axis=1) / shared[i],
                                   np.inf)
        total, count = 0.0, 0.0
        for axis in (1, 0):  # each track of a takes its nearest partner in b, then each track of b in a
            best = np.expand_dims(np.argmin(mean, axis=axis), axis)
            d = np.take_along_axis(mean, best, axis).squeeze(axis)
            n = np.take_along_axis(shared, best, axis).squeeze(axis)
            good = np.isfinite(d)
            total += float((d[good] * n[good]).sum())
            count += float(n[good].sum())
        if count:
            out[index] = total / count
    return out
