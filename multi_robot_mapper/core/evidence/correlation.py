"""Map correlation: every translation of one partial map over another at once.

INTEGRATE draws its hypotheses from landmarks, pairs of the longest segments. On large maps of
self-similar buildings (long corridors, rows of equal rooms) the true transformation is often
not among them, or a corridor slid along itself overlaps more. Correlation searches every
translation instead: the rotation comes from the maps' wall-direction histograms (the peaks of
their circular cross-correlation, as in Carpin's Hough-spectrum map merging) and, for each
rotation, the translation from the 2-D cross-correlation of the two maps drawn on a grid (one
FFT product per channel, :func:`scipy.signal.fftconvolve`).

Scores are in metres, like INTEGRATE's values: a wall lying on a wall of the same direction
counts its length; with the robots' free space (where their lasers saw nothing), a wall
placed in the other robot's free space counts ``free_space_weight`` times its length against
(the evidence that tells look-alike places apart, which overlap alone cannot). Walls are drawn
in three direction channels weighted ``2/3 cos^2(phi - k pi/3)``: the sum of the squared
weights is 1/2 for every direction, so parallel walls score the same whatever their direction
and crossing walls score a third of that.

Frames: :class:`Drawing` holds a map in its own frame; a transformation row ``(theta, tx,
ty)`` places map b in map a (INTEGRATE's convention, ``T_a_b``).
"""

from __future__ import annotations

import dataclasses
import functools

import numpy as np
from numpy.typing import NDArray
from scipy import fft as sp_fft
from scipy import ndimage

from multi_robot_mapper.core import se2
from multi_robot_mapper.core.geometry import sample_segments
from multi_robot_mapper.core.segment_map import MapLike, SegmentMap

FloatArray = NDArray[np.float64]


_CHANNELS = 3  # wall directions k * pi / 3; the weights' squares sum to 1/2 for any direction
_HISTOGRAM_BINS = 360  # wall directions over [0, pi): half-degree bins


@dataclasses.dataclass(frozen=True)
class CorrelationConfig:
    """How maps are drawn and correlated (metres, radians); plain values, not ROS parameters:
    :class:`multi_robot_mapper.core.merging.MergeConfig` holds the documented ones."""

    cell: float = 0.3  # grid cell (m)
    blur: float = 1.0  # Gaussian blur of the walls, in cells: tolerance for noise and drift
    free_space_weight: float = 1.0  # a metre of wall in free space cancels this many matched
    rotations: int = 4  # direction-histogram peaks tried (each also turned by pi)
    per_rotation: int = 8  # translation peaks kept per rotation
    separation: float = 1.0  # m, peaks closer than this are one answer


@dataclasses.dataclass(frozen=True)
class Drawing:
    """A map's walls as points along its segments (with each one's direction and length) and
    the points of its free space, in the map's own frame."""

    walls: FloatArray  # (P, 2)
    direction: FloatArray  # (P,) direction of the segment each point lies on (rad)
    weight: FloatArray  # (P,) metres of wall each point stands for
    free: FloatArray  # (F, 2) points where the robot's laser saw nothing

    @staticmethod
    def of(walls: MapLike, free: FloatArray, cell: float) -> Drawing:
        """Draw ``walls`` (sampled every half cell) with the free-space points ``free``."""
        spacing = 0.5 * cell
        if len(walls) == 0:
            empty = np.zeros(0)
            return Drawing(np.zeros((0, 2)), empty, empty, np.asarray(free).reshape(-1, 2))
        segment_map = SegmentMap.of(walls)
        segments, lines = segment_map.segments, segment_map.lines
        points, owner = sample_segments(segments, spacing)
        count = np.bincount(owner, minlength=len(segments))
        weight = (lines.length / np.maximum(count, 1))[owner]
        direction = np.arctan2(segments[:, 3] - segments[:, 1], segments[:, 2] - segments[:, 0])
        return Drawing(points, direction[owner], weight, np.asarray(free).reshape(-1, 2))

    def moved(self, T: FloatArray, theta: float) -> Drawing:
        """The same drawing moved by ``T`` (3x3), which turns it by ``theta``."""
        return Drawing(
            se2.transform_points(T, self.walls),
            self.direction + theta,
            self.weight,
            se2.transform_points(T, self.free),
        )

    def centre(self) -> FloatArray:
        """The middle of the drawing's bounding box (walls and free space)."""
        points = np.vstack((self.walls, self.free))
        return np.asarray(0.5 * (points.min(axis=0) + points.max(axis=0)))


@dataclasses.dataclass(frozen=True)
class _Grid:
    """A raster of cells ``cell`` wide; cell (i, j) is centred at ``origin + (i, j) * cell``."""

    origin: FloatArray  # (2,) centre of cell (0, 0)
    shape: tuple[int, int]
    cell: float

    @staticmethod
    def around(drawing: Drawing, cell: float) -> _Grid:
        """A grid holding the drawing, with one cell to spare on every side."""
        points = np.vstack((drawing.walls, drawing.free))
        if len(points) == 0:
            return _Grid(np.zeros(2), (1, 1), cell)
        low, high = points.min(axis=0) - cell, points.max(axis=0) + cell
        shape = np.ceil((high - low) / cell).astype(np.int64) + 1
        return _Grid(low, (int(shape[0]), int(shape[1])), cell)

    def coordinates(self, points: FloatArray) -> FloatArray:
        """(2, P) fractional cell indices of points."""
        return np.asarray(((points - self.origin) / self.cell).T)

    def draw(self, points: FloatArray, weights: FloatArray) -> FloatArray:
        """Sum of ``weights`` per cell, each point in its nearest cell."""
        u = np.rint(self.coordinates(points)).astype(np.int64)
        inside = (u[0] >= 0) & (u[1] >= 0) & (u[0] < self.shape[0]) & (u[1] < self.shape[1])
        index = u[0, inside] * self.shape[1] + u[1, inside]
        flat = np.bincount(index, weights[inside], minlength=self.shape[0] * self.shape[1])
        return np.asarray(flat.reshape(self.shape), dtype=np.float64)

    def mark(self, points: FloatArray) -> FloatArray:
        """1 in every cell holding a point (the nearest cell), else 0."""
        u = np.rint(self.coordinates(points)).astype(np.int64)
        inside = (u[0] >= 0) & (u[1] >= 0) & (u[0] < self.shape[0]) & (u[1] < self.shape[1])
        grid = np.zeros(self.shape)
        grid[u[0, inside], u[1, inside]] = 1.0
        return grid

    def sample(self, raster: FloatArray, points: FloatArray, order: int) -> FloatArray:
        """``raster`` at the points: bilinear (``order`` 1) or nearest cell (0); 0 outside."""
        return np.asarray(
            ndimage.map_coordinates(raster, self.coordinates(points), order=order, cval=0.0)
        )

    def nearest(self, raster: FloatArray, points: FloatArray) -> FloatArray:
        """``raster`` at the points' nearest cells (0 outside the grid), a block of points at
        a time (as :meth:`bilinear`)."""
        out = np.empty(len(points))
        for start in range(0, len(points), _READ_BLOCK):
            block = slice(start, start + _READ_BLOCK)
            out[block] = self.nearest_at(raster, self.coordinates(points[block]))
        return out

    def nearest_at(self, raster: FloatArray, u: FloatArray) -> FloatArray:
        """``raster`` at the nearest cells of the (2, P) fractional cell indices ``u`` (0
        outside the grid)."""
        cells = np.rint(u).astype(np.int64)
        inside = (cells[0] >= 0) & (cells[1] >= 0)
        inside &= (cells[0] < self.shape[0]) & (cells[1] < self.shape[1])
        out = np.zeros(u.shape[1])
        out[inside] = raster[cells[0, inside], cells[1, inside]]
        return out

    def bilinear(self, layers: FloatArray, points: FloatArray) -> FloatArray:
        """(C, P) each of the (H, W, C) ``layers`` at the points, interpolated between the four
        cells around each (a cell outside the grid reads 0): every layer from one gather."""
        flat = layers.reshape(self.shape[0] * self.shape[1], -1)
        out = np.empty((flat.shape[1], len(points)))
        # Points a block at a time: the same arithmetic per point, its temporaries held in
        # cache (a placement batch reads 10^5-10^6 points; whole, it ran at memory speed:
        # 1.4-1.7x slower on the evidence model's slides, issue 50).
        for start in range(0, len(points), _READ_BLOCK):
            block = slice(start, start + _READ_BLOCK)
            out[:, block] = self._bilinear_block(flat, points[block]).T
        return out

    def _bilinear_block(self, flat: FloatArray, points: FloatArray) -> FloatArray:
        """(P, C) of :meth:`bilinear` for a block of points, ``flat`` the layers (H W, C)."""
        u = self.coordinates(points)
        low = np.floor(u).astype(np.int64)
        frac = u - low
        height, width = self.shape
        out = np.zeros((len(points), flat.shape[1]))
        for di in (0, 1):
            i = low[0] + di
            share_i = frac[0] if di else 1.0 - frac[0]
            inside_i = (i >= 0) & (i < height)
            for dj in (0, 1):
                j = low[1] + dj
                share = share_i * (frac[1] if dj else 1.0 - frac[1])
                share = share * (inside_i & (j >= 0) & (j < width))
                index = np.clip(i, 0, height - 1) * width + np.clip(j, 0, width - 1)
                out += np.take(flat, index, axis=0) * share[:, None]
        return out


# Points read from a raster per block (_Grid.bilinear): 4096 x 3 channels of float64, a few
# hundred kB of temporaries.
_READ_BLOCK = 4096


def _channel_weights(direction: FloatArray) -> FloatArray:
    """(C, P) weights of each wall point in each direction channel."""
    k = np.arange(_CHANNELS)[:, None] * (np.pi / _CHANNELS)
    return np.asarray((2.0 / _CHANNELS) * np.cos(direction[None, :] - k) ** 2)


def _walls(drawing: Drawing, grid: _Grid, blur: float) -> FloatArray:
    """(C, H, W) metres of wall per cell and direction channel, blurred by ``blur`` cells."""
    weights = _channel_weights(drawing.direction) * drawing.weight[None, :]
    drawn = [grid.draw(drawing.walls, w) for w in weights]
    return np.stack([ndimage.gaussian_filter(d, blur, mode="constant") for d in drawn])


# Drawing a point in its nearest cell spreads a wall across by a uniform kernel of variance
# 1/12 cell^2; reading a raster between cells (bilinear) by a triangle of variance 1/6: the
# blur the metre scales must count.
_DRAWN = 1.0 / 12.0
_READ = 1.0 / 6.0


def _line_peak(cell: float, blur: float) -> float:
    """Correlation of two equal drawn walls per metre of wall (for the metre scale): the
    cross-profile of each is about a Gaussian of variance ``blur^2 + 1/12`` cells^2, their
    product sums to 1 / (2 sqrt(pi (blur^2 + 1/12))), times ``cell`` metres per cell, times
    the channels' 1/2."""
    return float(0.5 * cell / (2.0 * np.sqrt(np.pi * (blur**2 + _DRAWN))))


def wall_directions(walls: MapLike) -> FloatArray:
    """Length-weighted histogram of wall directions over [0, pi), blurred by one bin."""
    if len(walls) == 0:
        return np.zeros(_HISTOGRAM_BINS)
    segment_map = SegmentMap.of(walls)
    segments = segment_map.segments
    direction = np.arctan2(segments[:, 3] - segments[:, 1], segments[:, 2] - segments[:, 0])
    return _histogram(direction, segment_map.length)


def _histogram(direction: FloatArray, weight: FloatArray) -> FloatArray:
    """Weighted histogram of directions (rad, any) over [0, pi), blurred by one bin."""
    if len(direction) == 0:
        return np.zeros(_HISTOGRAM_BINS)
    folded = np.mod(direction, np.pi)
    bins = np.minimum((folded / np.pi * _HISTOGRAM_BINS).astype(np.int64), _HISTOGRAM_BINS - 1)
    histogram = np.bincount(bins, weights=weight, minlength=_HISTOGRAM_BINS)
    return np.asarray(ndimage.gaussian_filter1d(histogram, 1.0, mode="wrap"))


def rotation_candidates(map_a: MapLike, map_b: MapLike, count: int) -> FloatArray:
    """Rotations of map b that line its walls up with map a's: the ``count`` highest peaks
    (at least a fifth of the highest) of the circular cross-correlation of the two direction
    histograms, refined by a parabola through each peak, each also turned by pi (walls have no
    direction)."""
    return _rotation_peaks(wall_directions(map_a), wall_directions(map_b), count)


def _rotation_peaks(ha: FloatArray, hb: FloatArray, count: int) -> FloatArray:
    """:func:`rotation_candidates` from the two direction histograms."""
    spectrum = np.real(np.fft.ifft(np.fft.fft(ha) * np.conj(np.fft.fft(hb))))
    before, after = np.roll(spectrum, 1), np.roll(spectrum, -1)
    peaks = np.flatnonzero(
        (spectrum >= before) & (spectrum > after) & (spectrum >= 0.2 * spectrum.max())
    )
    peaks = peaks[np.argsort(-spectrum[peaks], kind="stable")][:count]
    curve = before[peaks] - 2.0 * spectrum[peaks] + after[peaks]
    safe = np.where(curve < 0.0, curve, -1.0)  # a flat top: no refinement
    offset = np.where(curve < 0.0, 0.5 * (before[peaks] - after[peaks]) / safe, 0.0)
    theta = (peaks + offset) * (np.pi / _HISTOGRAM_BINS)
    return np.asarray(se2.wrap_angle(np.concatenate((theta, theta + np.pi))))


@dataclasses.dataclass(frozen=True)
class CorrelationTarget:
    """Drawing a, transformed once for every drawing b up to ``reach`` metres from its middle
    (a map matched against many places keeps its transforms)."""

    grid: _Grid
    shape: tuple[int, int]
    walls: list[NDArray[np.complex64]]  # three wall-direction layers
    free: NDArray[np.complex64]
    sharp: NDArray[np.complex64]

    @staticmethod
    def of(a: Drawing, reach: float, cell: float, blur: float) -> CorrelationTarget:
        """``reach``: the largest distance of any drawing b's point from b's middle (m)."""
        grid = _Grid.around(a, cell)
        cells = int(np.ceil(2.0 * reach / cell)) + 2
        shape = (
            sp_fft.next_fast_len(grid.shape[0] + cells, real=True),
            sp_fft.next_fast_len(grid.shape[1] + cells, real=True),
        )
        return CorrelationTarget(
            grid,
            shape,
            [_spectrum(layer, shape) for layer in _walls(a, grid, blur)],
            _spectrum(grid.mark(a.free), shape),
            _spectrum(grid.draw(a.walls, a.weight), shape),  # free space is sharp: walls too
        )


def _spectrum(layer: FloatArray, shape: tuple[int, int]) -> NDArray[np.complex64]:
    # Single precision: scores are compared, not summed over many orders of magnitude, and
    # the transforms take half the time.
    return np.asarray(sp_fft.rfft2(layer.astype(np.float32), shape))


def reach_of(b: Drawing) -> float:
    """The largest distance of b's points (walls and free space) from its middle (m)."""
    points = np.vstack((b.walls, b.free))
    return float(np.hypot(*(points - b.centre()).T).max()) if len(points) else 0.0


def correlation_peaks(
    a: Drawing,
    b: Drawing,
    rotations: FloatArray,
    config: CorrelationConfig,
    target: CorrelationTarget | None = None,
) -> tuple[FloatArray, FloatArray]:
    """The best placements of drawing b on drawing a: ``(N, 3)`` rows ``(theta, tx, ty)`` and
    their scores (metres: matched wall minus ``free_space_weight`` x wall in the other's free
    space), best first; ``per_rotation`` peaks per rotation, ``separation`` apart.

    One FFT grid holds every shift of b over a (a's grid plus b's largest extent under any
    rotation, so the circular correlation never wraps a real overlap): a's five layers (three
    wall directions, its sharp walls, its free space) are transformed once (or come with
    ``target``, whose reach must cover b), b's five per rotation, and the score needs one
    inverse transform (correlation is linear).
    """
    cell, blur = config.cell, config.blur
    if len(a.walls) == 0 or len(b.walls) == 0:
        return np.zeros((0, 3)), np.zeros(0)
    # b turns about its own middle, so that its extent under any rotation is its diameter.
    middle = b.centre()
    reach = reach_of(b)
    if target is None or reach > target_reach(target, cell):
        target = CorrelationTarget.of(a, reach, cell, blur)
    b = b.moved(se2.matrix_from_pose(-float(middle[0]), -float(middle[1]), 0.0), 0.0)
    grid_a, shape = target.grid, target.shape
    scale = 1.0 / _line_peak(cell, blur)
    window = 2 * max(1, round(config.separation / cell)) + 1
    rows: list[FloatArray] = []
    scores: list[FloatArray] = []
    for theta in rotations:
        R = se2.matrix_from_pose(0.0, 0.0, float(theta))
        turned = b.moved(R, float(theta))
        grid_b = _Grid.around(turned, cell)
        walls_b = [_spectrum(layer, shape) for layer in _walls(turned, grid_b, blur)]
        free_b = _spectrum(grid_b.mark(turned.free), shape)
        sharp_b = _spectrum(grid_b.draw(turned.walls, turned.weight), shape)
        # Circular cross-correlation: entry k puts b's cell (0, 0) on a's cell k (k - shape
        # past a's grid: a negative shift). ``through`` is metres of wall in free cells.
        matched = sum(wa * np.conj(wb) for wa, wb in zip(target.walls, walls_b, strict=True))
        through = target.free * np.conj(sharp_b) + target.sharp * np.conj(free_b)
        score = sp_fft.irfft2(scale * matched - config.free_space_weight * through, shape)
        shift, values = _peaks(score, window, config.per_rotation)
        shift = np.where(shift < np.array(grid_a.shape), shift, shift - np.array(shape))
        # b's point p lands at R (p - middle) + t' = R p + t: t = t' - R middle.
        t = grid_a.origin - grid_b.origin + shift * cell - R[:2, :2] @ middle
        rows.append(np.column_stack((np.full(len(values), theta), t)))
        scores.append(values)
    if not rows:
        return np.zeros((0, 3)), np.zeros(0)
    all_rows, all_scores = np.vstack(rows), np.concatenate(scores)
    order = np.argsort(-all_scores, kind="stable")
    return all_rows[order], all_scores[order]


# Cells looked at per rotation for its peaks, per peak wanted: the highest cells.
_PEAK_POOL = 64


def _peaks(score: FloatArray, window: int, count: int) -> tuple[NDArray[np.int64], FloatArray]:
    """The ``count`` best local maxima of ``score`` (each the highest within ``window`` cells,
    circular; above 1 mm: below is rounding, not overlap), best first, looked for among a
    pool of the highest cells only (a maximum filter of the whole grid costs more than the
    correlation)."""
    flat = score.ravel()
    pool = min(flat.size, _PEAK_POOL * count)
    top = np.argpartition(-flat, pool - 1)[:pool] if pool < flat.size else np.arange(flat.size)
    top = top[flat[top] > 1e-3]
    rows, cols = np.unravel_index(top, score.shape)
    half = window // 2
    highest = np.full(len(top), True)
    for dr in range(-half, half + 1):
        for dc in range(-half, half + 1):
            if dr or dc:
                other = score[(rows + dr) % score.shape[0], (cols + dc) % score.shape[1]]
                highest &= flat[top] >= other
    order = np.argsort(-flat[top[highest]], kind="stable")[:count]
    chosen = top[highest][order]
    return np.column_stack(np.unravel_index(chosen, score.shape)), flat[chosen]


def target_reach(target: CorrelationTarget, cell: float) -> float:
    """The largest reach (m) of a drawing b that ``target``'s grid holds without wrapping."""
    spare = min(target.shape[0] - target.grid.shape[0], target.shape[1] - target.grid.shape[1])
    return 0.5 * (spare - 2) * cell


@dataclasses.dataclass(frozen=True)
class ScoringRasters:
    """A drawing's rasters for scoring placements directly: its grid, its blurred wall
    channels (None when only its free space is read) and its free cells."""

    grid: _Grid
    walls: FloatArray | None  # (H, W, C)
    free: FloatArray  # (H, W)

    @functools.cached_property
    def highest(self) -> FloatArray:
        """(H + 1, W + 1, C) the highest wall channel of each 2 x 2 block of cells, block
        (i, j) the cells (i - 1 .. i, j - 1 .. j) (outside the grid: 0), made once: what
        :func:`score_bound` reads."""
        assert self.walls is not None
        padded = np.pad(self.walls, ((1, 1), (1, 1), (0, 0)))
        pairs = np.maximum(padded[:-1, :-1], padded[1:, :-1])
        return np.maximum(pairs, np.maximum(padded[:-1, 1:], padded[1:, 1:]))


def scorer_rasters(
    drawing: Drawing, cell: float, blur: float, walls: bool = True
) -> ScoringRasters:
    """The rasters :func:`score_parts` reads of a drawing, ``cell`` (m) wide, the walls
    blurred by ``blur`` cells (``walls``: its wall channels too, for the drawing others are
    placed on)."""
    grid = _Grid.around(drawing, cell)
    channels = (
        np.ascontiguousarray(np.moveaxis(_walls(drawing, grid, blur), 0, -1)) if walls else None
    )
    return ScoringRasters(grid, channels, grid.mark(drawing.free))


def score_parts(
    a: Drawing,
    b: Drawing,
    transforms: FloatArray,
    rasters_a: ScoringRasters,
    rasters_b: ScoringRasters,
    blur_cell: tuple[float, float],
    walls_a: tuple[FloatArray, FloatArray] | None = None,
) -> tuple[FloatArray, FloatArray]:
    """The two parts of each placement's score: (N,) metres of wall matched and (N,) metres
    of wall in the other's free space, either way (b's points under every transform sampled
    together), on rasters of ``blur_cell``: (the walls' blur in cells, the cell in metres).
    ``walls_a``: the (points, weights) of a's walls that can reach b's free space under these
    placements (default all of them)."""
    rows = np.asarray(transforms, dtype=np.float64).reshape(-1, 3)
    if len(rows) == 0:
        return np.zeros(0), np.zeros(0)
    assert rasters_a.walls is not None
    # A wall point on a drawn wall of its direction reads 1 / sqrt(2 pi (blur^2 + 1/12 +
    # 1/6)) of the wall's metres per cell (blur, drawing, reading): that, times the channels'
    # 1/2, is one metre per metre.
    blur, cell = blur_cell
    scale = np.sqrt(2.0 * np.pi * (blur**2 + _DRAWN + _READ)) / (0.5 * cell)
    T = se2.matrices_from_poses(rows[:, [1, 2, 0]])  # (N, 3, 3) T_a_b
    on_a = np.matmul(b.walls[None, :, :], T[:, :2, :2].transpose(0, 2, 1)) + T[:, None, :2, 2]
    flat = on_a.reshape(-1, 2)
    read = rasters_a.grid.bilinear(rasters_a.walls, flat)
    matched = _matched_metres(read.reshape(_CHANNELS, len(rows), -1), b, rows[:, 0], scale)
    through = rasters_a.grid.nearest(rasters_a.free, flat).reshape(len(rows), -1) @ b.weight
    points_a, weight_a = (a.walls, a.weight) if walls_a is None else walls_a
    if len(points_a):
        T_b_a = np.linalg.inv(T)
        on_b = np.matmul(points_a[None, :, :], T_b_a[:, :2, :2].transpose(0, 2, 1))
        on_b = on_b + T_b_a[:, None, :2, 2]
        seen = rasters_b.grid.nearest(rasters_b.free, on_b.reshape(-1, 2))
        through = through + seen.reshape(len(rows), -1) @ weight_a
    return np.asarray(matched), np.asarray(through)


def score_bound(
    b: Drawing,
    transforms: FloatArray,
    rasters_a: ScoringRasters,
    blur_cell: tuple[float, float],
    free_space_weight: float,
) -> FloatArray:
    """(N,) an upper bound of each placement's score (:func:`score_parts`: matched minus
    ``free_space_weight`` x in free space): each of b's wall points reads the highest of the
    four cells a bilinear read weighs (:attr:`ScoringRasters.highest`, one gather instead of
    four), and only b's walls in a's free space count against (a's in b's only lower the
    score); a little above, for rounding."""
    rows = np.asarray(transforms, dtype=np.float64).reshape(-1, 3)
    if len(rows) == 0:
        return np.zeros(0)
    blur, cell = blur_cell
    scale = np.sqrt(2.0 * np.pi * (blur**2 + _DRAWN + _READ)) / (0.5 * cell)
    T = se2.matrices_from_poses(rows[:, [1, 2, 0]])
    on_a = np.matmul(b.walls[None, :, :], T[:, :2, :2].transpose(0, 2, 1)) + T[:, None, :2, 2]
    points = on_a.reshape(-1, 2)
    grid, highest = rasters_a.grid, rasters_a.highest
    flat = highest.reshape(-1, highest.shape[2])
    read = np.empty((flat.shape[1], len(points)))
    free = np.empty(len(points))  # a's free space at each point's nearest cell
    for start in range(0, len(points), _READ_BLOCK):
        block = slice(start, start + _READ_BLOCK)
        u = grid.coordinates(points[block])
        low = np.floor(u).astype(np.int64) + 1  # into highest
        inside = (low[0] >= 0) & (low[1] >= 0)
        inside &= (low[0] < highest.shape[0]) & (low[1] < highest.shape[1])
        index = np.where(inside, low[0] * highest.shape[1] + low[1], 0)
        read[:, block] = (np.take(flat, index, axis=0) * inside[:, None]).T
        free[block] = grid.nearest_at(rasters_a.free, u)
    matched = _matched_metres(read.reshape(_CHANNELS, len(rows), -1), b, rows[:, 0], scale)
    through = free.reshape(len(rows), -1) @ b.weight
    # The bilinear shares sum to 1 and the channel weights are >= 0, up to rounding.
    slack = 1e-9 * (np.abs(matched) + free_space_weight * np.abs(through) + 1.0)
    return np.asarray(matched - free_space_weight * through + slack)


def weakest_direction(
    a: Drawing, b: Drawing, row: FloatArray, rasters_a: ScoringRasters
) -> FloatArray:
    """The unit vector (in a's frame) along which b's walls matched on a at the placement
    ``row`` (theta, tx, ty) hold it least: the eigenvector of the smaller eigenvalue of
    sum_p m_p n_p n_p^T over b's wall points (m_p the metres point p matches, n_p its wall's
    normal, turned by theta). Along a bare corridor it is the corridor's direction: a slide
    along it keeps most of the wall on wall."""
    theta, tx, ty = (float(v) for v in np.asarray(row, dtype=np.float64).reshape(3))
    if len(b.walls) == 0:
        return np.array([1.0, 0.0])
    assert rasters_a.walls is not None
    c, s = np.cos(theta), np.sin(theta)
    on_a = b.walls @ np.array([[c, s], [-s, c]]) + np.array([tx, ty])
    read = rasters_a.grid.bilinear(rasters_a.walls, on_a).reshape(_CHANNELS, -1)  # (C, P)
    # As score_parts: channel k weighs a point of direction phi by (1 + cos 2(phi - k pi/C)).
    k = np.arange(_CHANNELS)[:, None] * (np.pi / _CHANNELS)
    turned = b.direction + theta
    share = (read * (1.0 + np.cos(2.0 * (turned[None, :] - k)))).sum(axis=0)
    metres = np.clip(share, 0.0, None) * b.weight
    normal = np.stack((-np.sin(turned), np.cos(turned)), axis=1)  # (P, 2)
    _, vectors = np.linalg.eigh((normal * metres[:, None]).T @ normal)
    return np.asarray(vectors[:, 0])


def _matched_metres(read: FloatArray, b: Drawing, theta: FloatArray, scale: float) -> FloatArray:
    """(N,) metres of b's wall matched under each of N rotations ``theta``: each point's
    channel reads ``read`` (C, N, P) weighted by 2/3 cos^2 of its direction turned by theta
    against the channel's (1/3 (1 + cos 2(phi + theta - k pi/3))), times ``scale``, at most
    one metre per metre of wall. Where a's walls are drawn twice
    (two parallel walls within the blur, a map that holds a wall twice) a point reads more than
    one: uncapped, a patch matched more metres than it has (generated building 180: 90 m of
    a 49 m patch, placed 11 m off at P 0.992)."""
    k = np.arange(_CHANNELS)[:, None] * (np.pi / _CHANNELS)
    double = 2.0 * (b.direction[None, :] - k)  # (C, P)
    if len(theta) > 1 and bool(np.all(theta == theta[0])):
        # One rotation for every placement (a placement's slides): the weights once, (C, 1,
        # P), broadcast over the placements (the same numbers, without N copies of them).
        theta = theta[:1]
    c, s = np.cos(2.0 * theta), np.sin(2.0 * theta)  # (N,)
    weights = (
        1.0
        + np.cos(double)[:, None, :] * c[None, :, None]
        - np.sin(double)[:, None, :] * s[None, :, None]
    )  # (C, N, P): 3/2 cos^2 of each point's direction against each channel's, turned
    per_metre = (read * weights).sum(axis=0) * (scale / _CHANNELS)  # (N, P)
    return np.asarray(np.clip(per_metre, 0.0, 1.0) @ b.weight)


def placement_scores(
    a: Drawing, b: Drawing, transforms: FloatArray, config: CorrelationConfig
) -> FloatArray:
    """The correlation score (metres) of each ``(theta, tx, ty)`` placement of b on a,
    evaluated directly (b's wall points looked up in a's blurred walls and free space, a's
    wall points in b's free space): for placements found elsewhere, e.g. refined ones."""
    rasters_a = scorer_rasters(a, config.cell, config.blur)
    rasters_b = scorer_rasters(b, config.cell, config.blur, walls=False)
    blur_cell = (config.blur, config.cell)
    matched, through = score_parts(a, b, transforms, rasters_a, rasters_b, blur_cell)
    return np.asarray(matched - config.free_space_weight * through)


def rotation_candidates_of_drawings(a: Drawing, b: Drawing, count: int) -> FloatArray:
    """:func:`rotation_candidates` of two drawings (their wall points' directions, weighted
    by the metres each stands for)."""
    return _rotation_peaks(
        _histogram(a.direction, a.weight), _histogram(b.direction, b.weight), count
    )
