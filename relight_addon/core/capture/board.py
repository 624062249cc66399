# SPDX-License-Identifier: GPL-3.0-or-later
"""ChArUco boards: the pattern, its printable files, and its corners found in a photo.

The board is ``cv2.aruco.CharucoBoard((squares_x, squares_y), square_length, marker_length,
dictionary)`` with OpenCV's current (non-legacy) layout.  Its frame (OpenCV's): origin at the
printed image's top-left corner, X right, Y down the image, Z into the board; chessboard corner
``i`` of ``board.getChessboardCorners()`` is the charuco id ``i``.

Detection re-refines the corners OpenCV 4.11's ``CharucoDetector`` returns with
``cv2.cornerSubPix``: the detector shifts every corner by about +0.5 px in x and y
(opencv/opencv#25539, fixed by #28380 after 4.11), and ``cornerSubPix`` converges to the saddle
point whatever the starting offset (so the re-refinement stays right once OpenCV is fixed).
The markers are painted over first (their edges would pull the corners), which lets the window
grow to nearly half the square, and the image is smoothed a little (against pixel locking).

Files: the PNG is the board alone, without margin (what "Images as Planes" turns into a plane
of the board's size), with its print resolution (pHYs) set so that a square prints at
``square_length``; the PDF is a page of the chosen paper with the board centred at scale 1 and
a line of text giving the square size, the marker size and the dictionary.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from . import CaptureError

# Paper sizes (width, height) in millimetres, portrait.
PAPERS = {"A5": (148.0, 210.0), "A4": (210.0, 297.0), "A3": (297.0, 420.0),
          "A2": (420.0, 594.0), "A1": (594.0, 841.0), "A0": (841.0, 1189.0),
          "LETTER": (215.9, 279.4), "LEGAL": (215.9, 355.6), "TABLOID": (279.4, 431.8)}
# White paper kept around the board on the PDF page (printers do not print to the edge).
PAGE_MARGIN_MM = 10.0
# Room under the board for the line of text on the PDF page.
LABEL_MM = 8.0
# Print resolution of the files (dots per inch), before rounding a square to whole pixels.
PRINT_DPI = 300.0
MM_PER_INCH = 25.4
# Re-refinement: the markers are painted over with the white around them (their edges would
# pull the corners), the image is smoothed by a Gaussian of PRE_BLUR_PX (cornerSubPix on sharp,
# 1-2 px edges is biased by the corner's sub-pixel phase, "pixel locking": 0.03-0.05 px on
# noise-free images, 0.006-0.01 px after a 1.5 px blur), then cornerSubPix runs with a window
# of half size WINDOW_FRACTION of the local square side (the nearest marker's shortest side /
# its share of the square).  Measured on 72 renders of 20-60 px squares at 16 samples, RMS
# error per axis: markers kept and a window clear of them 0.077 px; markers painted over,
# window 0.35 of the side 0.040 px; and the blur, window 0.45: 0.027 px.
WINDOW_FRACTION = 0.45
PRE_BLUR_PX = 1.5
# ... and at most this fraction of the median square side (small squares)
PRE_BLUR_FRACTION = 0.06
# ... clamped to this range (pixels)
WINDOW_MIN, WINDOW_MAX = 2, 20
# the painted quad is each marker grown by this many pixels (its anti-aliased edge)
MARKER_GROW_PX = 2.0
# the white level is the median of the ring between these scales of the marker about its centre
WHITE_RING = (1.1, 1.25)
SUBPIX_CRITERIA = (3, 100, 1e-5)
# grey levels (of 255) between the 2nd and 98th percentiles below which blur is not measured
MIN_CONTRAST = 24   # cv2.TERM_CRITERIA_EPS | COUNT, iterations, epsilon (px)


def _cv2():
    import cv2  # noqa: PLC0415  (a declared dependency, imported when capture is used)
    return cv2


def dictionary_names() -> list:
    """Names of cv2.aruco's predefined dictionaries (``DICT_5X5_100`` ...)."""
    cv2 = _cv2()
    return sorted(n for n in dir(cv2.aruco) if n.startswith("DICT_")
                  and isinstance(getattr(cv2.aruco, n), int))


def get_dictionary(name: str):
    cv2 = _cv2()
    value = getattr(cv2.aruco, str(name), None)
    if not str(name).startswith("DICT_") or not isinstance(value, int):
        raise CaptureError(f"'{name}' is not a cv2.aruco predefined dictionary "
                           f"(e.g. DICT_5X5_100)")
    return cv2.aruco.getPredefinedDictionary(value)


@dataclass(frozen=True)
class BoardSpec:
    """A ChArUco board: squares across and down, square and marker sides (metres)."""

    squares_x: int
    squares_y: int
    square_length: float
    marker_length: float
    dictionary: str = "DICT_5X5_100"

    def validate(self) -> "BoardSpec":
        if self.squares_x < 2 or self.squares_y < 2:
            raise CaptureError(f"A ChArUco board needs at least 2 x 2 squares, not "
                               f"{self.squares_x} x {self.squares_y}")
        if not (np.isfinite(self.square_length) and self.square_length > 0):
            raise CaptureError(f"The square length must be positive, not {self.square_length}")
        if not (0 < self.marker_length < self.square_length):
            raise CaptureError(f"The marker length ({self.marker_length:g} m) must be positive "
                               f"and smaller than the square length ({self.square_length:g} m)")
        d = get_dictionary(self.dictionary)
        n = self.n_markers
        if n > d.bytesList.shape[0]:
            raise CaptureError(f"A {self.squares_x} x {self.squares_y} board needs {n} markers; "
                               f"{self.dictionary} has only {d.bytesList.shape[0]}")
        return self

    @property
    def n_markers(self) -> int:
        return (self.squares_x * self.squares_y) // 2

    @property
    def n_corners(self) -> int:
        return (self.squares_x - 1) * (self.squares_y - 1)

    @property
    def size(self) -> tuple:
        """(width, height) of the board in metres."""
        return self.squares_x * self.square_length, self.squares_y * self.square_length

    def board(self):
        cv2 = _cv2()
        self.validate()
        b = cv2.aruco.CharucoBoard((int(self.squares_x), int(self.squares_y)),
                                   float(self.square_length), float(self.marker_length),
                                   get_dictionary(self.dictionary))
        b.setLegacyPattern(False)
        return b

    def describe(self) -> str:
        return (f"{self.squares_x} x {self.squares_y} ChArUco board, "
                f"{1000 * self.square_length:g} mm squares, {1000 * self.marker_length:g} mm "
                f"markers, {self.dictionary}")

    def corner_points(self) -> np.ndarray:
        """(n_corners, 3) chessboard corners in the board frame (metres), by charuco id."""
        return np.asarray(self.board().getChessboardCorners(), np.float64).reshape(-1, 3)


# ------------------------------------------------------------------------------------------
# Printable files
# ------------------------------------------------------------------------------------------

def square_pixels(spec: BoardSpec, dpi: float = PRINT_DPI) -> int:
    """Whole pixels a square takes at about ``dpi`` (the files' resolution is then adjusted
    so that the square prints at exactly ``square_length``)."""
    return max(8, int(round(spec.square_length * 1000 / MM_PER_INCH * dpi)))


def board_image(spec: BoardSpec, pixels_per_square: int) -> np.ndarray:
    """The board alone (no margin), (squares_y * p, squares_x * p) uint8, white = 255."""
    p = int(pixels_per_square)
    return spec.board().generateImage((spec.squares_x * p, spec.squares_y * p), marginSize=0,
                                      borderBits=1)


def _exact_dpi(spec, px):
    """The resolution at which ``px`` pixels measure one square."""
    return px / (spec.square_length * 1000 / MM_PER_INCH)


def write_png(spec: BoardSpec, path: str, dpi: float = PRINT_DPI) -> dict:
    """The board as a PNG whose print resolution makes a square ``square_length`` wide."""
    from PIL import Image, PngImagePlugin  # noqa: PLC0415
    px = square_pixels(spec, dpi)
    img = board_image(spec, px)
    info = PngImagePlugin.PngInfo()
    info.add_text("Description", spec.describe())
    info.add_text("relight-board", f"{spec.squares_x} {spec.squares_y} {spec.square_length!r} "
                                   f"{spec.marker_length!r} {spec.dictionary}")
    exact = _exact_dpi(spec, px)
    Image.fromarray(img).save(path, dpi=(exact, exact), pnginfo=info)
    return {"pixels_per_square": px, "dpi": exact, "shape": img.shape}


def page_layout(spec: BoardSpec, paper: str = "A4") -> dict:
    """Paper size (mm, in the orientation used) and whether it is landscape; raises when the
    board (with the margins and the label) does not fit either way."""
    key = str(paper).upper()
    if key not in PAPERS:
        raise CaptureError(f"Unknown paper '{paper}' (one of {', '.join(PAPERS)})")
    pw, ph = PAPERS[key]
    bw, bh = (1000 * s for s in spec.size)
    need_w, need_h = bw + 2 * PAGE_MARGIN_MM, bh + 2 * PAGE_MARGIN_MM + LABEL_MM
    for w, h, landscape in ((pw, ph, False), (ph, pw, True)):
        if need_w <= w and need_h <= h:
            return {"paper": key, "width_mm": w, "height_mm": h, "landscape": landscape}
    raise CaptureError(f"The {spec.squares_x} x {spec.squares_y} board of "
                       f"{1000 * spec.square_length:g} mm squares ({bw:.0f} x {bh:.0f} mm) does "
                       f"not fit on {key} ({pw:g} x {ph:g} mm) with {PAGE_MARGIN_MM:g} mm margins: "
                       f"choose larger paper or smaller squares")


def write_pdf(spec: BoardSpec, path: str, paper: str = "A4", dpi: float = PRINT_DPI) -> dict:
    """One page of ``paper`` with the board centred at scale 1 and its sizes printed under it."""
    from PIL import Image  # noqa: PLC0415
    cv2 = _cv2()
    layout = page_layout(spec, paper)
    px = square_pixels(spec, dpi)
    exact = _exact_dpi(spec, px)
    mm = exact / MM_PER_INCH                           # pixels per millimetre
    page_w, page_h = int(round(layout["width_mm"] * mm)), int(round(layout["height_mm"] * mm))
    page = np.full((page_h, page_w), 255, np.uint8)
    img = board_image(spec, px)
    top = max(0, (page_h - img.shape[0] - int(LABEL_MM * mm)) // 2)
    left = (page_w - img.shape[1]) // 2
    page[top:top + img.shape[0], left:left + img.shape[1]] = img
    text = (f"ChArUco {spec.squares_x} x {spec.squares_y}: square {1000 * spec.square_length:g} mm, "
            f"marker {1000 * spec.marker_length:g} mm, {spec.dictionary}.  Print at 100 % "
            f"(no scaling) and check that a square measures {1000 * spec.square_length:g} mm.")
    # Hershey text scaled to fit the board's width, about 3 mm high.
    scale = 3.0 * mm / 22.0
    (tw, _), _ = cv2.getTextSize(text, cv2.FONT_HERSHEY_SIMPLEX, scale, 1)
    scale *= min(1.0, (page_w - 2 * PAGE_MARGIN_MM * mm) / max(tw, 1))
    (tw, th), _ = cv2.getTextSize(text, cv2.FONT_HERSHEY_SIMPLEX, scale, 1)
    thick = max(1, int(round(0.25 * mm)))
    org = ((page_w - tw) // 2, top + img.shape[0] + int(round(4.0 * mm)) + th)
    cv2.putText(page, text, org, cv2.FONT_HERSHEY_SIMPLEX, scale, 0, thick, cv2.LINE_8)
    # bilevel: Pillow stores it losslessly (CCITT G4) where grey would be JPEG
    bilevel = Image.fromarray(page).convert("1", dither=Image.Dither.NONE)
    bilevel.save(path, "PDF", resolution=exact, title=spec.describe())
    return dict(layout, dpi=exact, pixels=(page_w, page_h), label=text)


# ------------------------------------------------------------------------------------------
# Detection
# ------------------------------------------------------------------------------------------

@dataclass
class Detection:
    """Charuco corners found in one image (pixel coordinates, OpenCV's: the centre of the
    top-left pixel is (0, 0)).

    corners      (n, 2) float64  re-refined with cornerSubPix (what the maths uses)
    ids          (n,) int        charuco corner ids
    raw          (n, 2) float64  as CharucoDetector returned them (plain OpenCV)
    marker_ids   (m,) int        markers of the board found
    foreign_ids  (k,) int        markers of the dictionary that are not on this board
    blur         float           estimated blur (Gaussian sigma, px) of the board's edges
    """

    corners: np.ndarray
    ids: np.ndarray
    raw: np.ndarray
    marker_ids: np.ndarray = field(default_factory=lambda: np.zeros(0, int))
    foreign_ids: np.ndarray = field(default_factory=lambda: np.zeros(0, int))
    blur: float = float("nan")

    def __len__(self):
        return len(self.ids)


def to_gray(image) -> np.ndarray:
    """uint8 grey image from (H, W), (H, W, 3) BGR or (H, W, 4); floats are taken as [0, 1]."""
    cv2 = _cv2()
    a = np.asarray(image)
    if a.dtype != np.uint8:
        a = np.clip(np.nan_to_num(a.astype(np.float64)) * 255.0 + 0.5, 0, 255).astype(np.uint8)
    if a.ndim == 3:
        a = cv2.cvtColor(a, cv2.COLOR_BGRA2GRAY if a.shape[2] == 4 else cv2.COLOR_BGR2GRAY)
    return np.ascontiguousarray(a)


class Detector:
    """CharucoDetector for one board, followed by the cornerSubPix re-refinement."""

    def __init__(self, spec: BoardSpec):
        cv2 = _cv2()
        self.spec = spec.validate()
        self.board = spec.board()
        self._charuco = cv2.aruco.CharucoDetector(self.board)
        self._aruco = cv2.aruco.ArucoDetector(get_dictionary(spec.dictionary))

    def detect(self, image, refine: bool = True) -> Detection:
        gray = to_gray(image)
        cc, ids, mc, mids = self._charuco.detectBoard(gray)
        board_ids = set(np.asarray(self.board.getIds()).ravel().tolist())
        if mids is None or len(mids) == 0:
            _, all_ids, _ = self._aruco.detectMarkers(gray)
            found = np.zeros(0, int) if all_ids is None else np.asarray(all_ids).ravel()
            mids = np.zeros(0, int)
        else:
            found = np.asarray(mids).ravel()
        foreign = np.array(sorted(set(found.tolist()) - board_ids), int)
        if cc is None or ids is None or len(ids) == 0:
            empty = np.zeros((0, 2))
            return Detection(empty, np.zeros(0, int), empty, np.asarray(mids).ravel(), foreign,
                             edge_blur(gray))
        raw = np.asarray(cc, np.float64).reshape(-1, 2)
        ids = np.asarray(ids).ravel().astype(int)
        corners = raw.copy()
        if refine:
            corners = refine_corners(gray, raw, mc, self.spec.marker_length / self.spec.square_length)
        return Detection(corners, ids, raw, np.asarray(mids).ravel().astype(int), foreign,
                         edge_blur(gray, corners))


def erase_markers(gray, marker_corners) -> np.ndarray:
    """A copy of the image with every marker (grown by MARKER_GROW_PX) painted with the median
    of the white ring around it."""
    cv2 = _cv2()
    out = gray.copy()
    shift = 4                                        # fixed-point polygons: 1/16 px
    for quad in marker_corners:
        q = np.asarray(quad, np.float64).reshape(4, 2)
        c = q.mean(axis=0)
        outer = np.zeros(gray.shape, np.uint8)
        inner = np.zeros(gray.shape, np.uint8)
        cv2.fillConvexPoly(outer, np.round((c + (q - c) * WHITE_RING[1]) * 16).astype(np.int32), 1,
                           shift=shift)
        cv2.fillConvexPoly(inner, np.round((c + (q - c) * WHITE_RING[0]) * 16).astype(np.int32), 1,
                           shift=shift)
        ring = (outer > 0) & (inner == 0)
        level = int(np.median(gray[ring])) if ring.any() else 255
        d = q - c
        grown = q + d / np.maximum(np.linalg.norm(d, axis=1, keepdims=True), 1e-9) \
            * MARKER_GROW_PX * np.sqrt(2.0)
        cv2.fillConvexPoly(out, np.round(grown * 16).astype(np.int32), level, shift=shift)
    return out


def refine_corners(gray, corners, marker_corners, marker_ratio) -> np.ndarray:
    """cornerSubPix of every corner on the image with its markers painted over and smoothed,
    with a window of WINDOW_FRACTION of the local square side."""
    cv2 = _cv2()
    corners = np.asarray(corners, np.float64).reshape(-1, 2)
    half = np.full(len(corners), WINDOW_MIN)
    img = gray.astype(np.float32)
    blur = PRE_BLUR_PX
    if marker_corners is not None and len(marker_corners):
        quads = np.stack([np.asarray(m, np.float64).reshape(4, 2) for m in marker_corners])
        img = erase_markers(gray, quads).astype(np.float32)
        centre = quads.mean(axis=1)
        square = np.linalg.norm(np.roll(quads, -1, axis=1) - quads, axis=2).min(axis=1) / marker_ratio
        near = np.argmin(((corners[:, None, :] - centre[None]) ** 2).sum(-1), axis=1)
        half = np.round(WINDOW_FRACTION * square[near])
        blur = min(PRE_BLUR_PX, PRE_BLUR_FRACTION * float(np.median(square)))
    if blur > 0.3:
        img = cv2.GaussianBlur(img, (0, 0), blur)
    half = np.clip(half, WINDOW_MIN, WINDOW_MAX).astype(int)
    out = corners.copy()
    crit = (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT,) + SUBPIX_CRITERIA[1:]
    for w in np.unique(half):
        sel = np.flatnonzero(half == w)
        pts = np.ascontiguousarray(corners[sel].reshape(-1, 1, 2), np.float32)
        out[sel] = cv2.cornerSubPix(img, pts, (int(w), int(w)), (-1, -1), crit).reshape(-1, 2)
    # a corner that ran away (a window that met another edge) keeps its detector position
    moved = np.sqrt(((out - corners) ** 2).sum(-1))
    bad = ~np.isfinite(moved) | (moved > np.maximum(0.5 * half, 2))
    out[bad] = corners[bad]
    return out


def edge_blur(gray, corners=None) -> float:
    """Blur of the board's edges as the sigma (px) of a Gaussian: an ideal step of contrast C
    blurred by sigma has a steepest gradient C / (sigma sqrt(2 pi)).  Measured over the
    corners' convex hull, or the whole image without corners (contrast: 2nd-98th percentile;
    gradient: 99.5th percentile); NaN where there is no contrast to measure."""
    cv2 = _cv2()
    if corners is None:
        sel = np.ones(gray.shape, bool)
    else:
        pts = np.asarray(corners, np.float32).reshape(-1, 2)
        if len(pts) < 3:
            return float("nan")
        hull = cv2.convexHull(pts).astype(np.int32)
        mask = np.zeros(gray.shape, np.uint8)
        cv2.fillConvexPoly(mask, hull, 1)
        sel = mask.astype(bool)
    if sel.sum() < 64:
        return float("nan")
    g = gray.astype(np.float32)
    gx = cv2.Sobel(g, cv2.CV_32F, 1, 0, ksize=3) / 8.0
    gy = cv2.Sobel(g, cv2.CV_32F, 0, 1, ksize=3) / 8.0
    mag = np.sqrt(gx * gx + gy * gy)[sel]
    lo, hi = np.percentile(g[sel], [2, 98])
    peak = np.percentile(mag, 99.5)
    if hi - lo < MIN_CONTRAST or peak <= 0:
        return float("nan")
    return float((hi - lo) / (peak * np.sqrt(2 * np.pi)))
