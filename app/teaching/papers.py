"""The source papers' published numbers, each with the table, figure or section it is in.

The benchmarks and ``voxwarp reproduce`` put these beside voxwarp's measurements. Only
numbers printed in the papers are here (``../shared/papers/`` holds their text); ratios
are derived from them by the functions below, never typed in, so a misquote shows as a
failing test (``tests/teaching/test_papers.py``).

* **Wire paper** (Journal of WSCG 14, 2006; non-reconstructive volume deformation by
  sweeping along wires): Table 1 (ray samples ignored), Tables 2 and 3 (standard render
  vs identity deformation, a software raycaster at 512x256 on a 3.2 GHz Pentium 4),
  Figure 12 (attribute field build time per field scale), section 7.2 (storage).
* **GRAPP 2010 lattice paper** (trilinear transformations in a scene graph): the frame
  rate table of section 6 (linear vs trilinear, GeForce 8800).
* **Thesis 2008** (mass-spring systems and 3D ChainMail on the GPU): no measured numbers;
  its results chapter shows images only (Figures 12-13).
"""

from __future__ import annotations

from dataclasses import dataclass

#: what a table says where the paper has no number for a row
PAPER_HAS_NONE = "none in the paper"


@dataclass(frozen=True)
class WireTable1Row:
    """Wire paper, Table 1: ray samples inside the attribute field that need no mapping."""

    dataset: str
    samples: int
    ignored: int
    percent: float  # as printed

    @property
    def percent_computed(self) -> float:
        """``ignored / samples`` in %, from the printed counts."""
        return 100.0 * self.ignored / self.samples


#: Table 1 ("Voxels ignored while rendering"): samples outside the field are not counted
WIRE_TABLE1: tuple[WireTable1Row, ...] = (
    WireTable1Row("CT Carp", 26_011_195, 15_523_566, 59.7),
    WireTable1Row("Visman", 45_461_270, 39_253_862, 86.3),
)


@dataclass(frozen=True)
class WireTimingRow:
    """Wire paper, Tables 2 and 3 for one dataset (seconds, identity deformation)."""

    dataset: str
    standard_s: float  # Table 2: the raycaster without deformation
    preprocessing_s: float  # Table 3: attribute field, masks, lookup tables
    render_s: float  # Table 3: render with the (identity) deformation
    total_s: float  # Table 3, as printed

    @property
    def render_ratio(self) -> float:
        """Deformed render / standard render (Table 3 / Table 2)."""
        return self.render_s / self.standard_s

    @property
    def total_ratio(self) -> float:
        """(Preprocessing + render) / standard render (Table 3 total / Table 2)."""
        return self.total_s / self.standard_s


WIRE_TIMINGS: tuple[WireTimingRow, ...] = (
    WireTimingRow("CT Carp", 5.74, 1.78, 12.65, 14.43),
    WireTimingRow("Tubes", 2.59, 0.96, 4.81, 5.77),
    WireTimingRow("Visman torso", 4.31, 2.97, 22.87, 25.84),
)
#: image size and machine of Tables 2-3 (section 9)
WIRE_TIMING_IMAGE: tuple[int, int] = (512, 256)
WIRE_TIMING_MACHINE = "Pentium 4, 3.2 GHz, 512 MB, software raycaster"

#: Figure 12 (Visible Human, head pulled back): field build seconds per field scale
#: (per-axis reduction 1, 2, 4, 8, 16 = voxel ratios 1:1 ... 1:4096)
WIRE_FIG12_BUILD_S: dict[int, float] = {1: 11.74, 2: 4.45, 4: 2.61, 8: 2.17, 16: 2.12}

#: section 7.2: bytes per voxel with a float t (a minimum of 5), and the 2-byte example
#: layout's bits (flag, wire, segment, t within the segment)
WIRE_FLOAT_BYTES_PER_VOXEL = 5
WIRE_PAPER_LAYOUT_BITS: tuple[int, int, int, int] = (1, 4, 4, 7)


@dataclass(frozen=True)
class LatticeFpsRow:
    """GRAPP 2010, section 6 table: frames per second, linear (4x4) vs trilinear."""

    scene: str
    measures: str  # what the row loads: the GPU's vertex stage or the CPU's composition
    objects: int
    triangles: str  # as printed ("1.5M", "164k", "656k")
    linear_fps: float
    trilinear_fps: float

    @property
    def ratio(self) -> float:
        """Trilinear / linear frame rate."""
        return self.trilinear_fps / self.linear_fps

    @property
    def triangle_count(self) -> int:
        """The printed triangle count as a number ("1.5M" -> 1,500,000)."""
        scale = {"k": 1_000, "M": 1_000_000}[self.triangles[-1]]
        return round(float(self.triangles[:-1]) * scale)


LATTICE_FPS: tuple[LatticeFpsRow, ...] = (
    LatticeFpsRow("spheres", "GPU vertex throughput", 185, "1.5M", 19.5, 14.9),
    LatticeFpsRow("helix", "CPU composition", 4617, "164k", 16.5, 13.3),
    LatticeFpsRow("helix", "CPU composition", 2566, "656k", 10.8, 8.4),
)
#: section 6: the trilinear part of the vertex shader is "roughly two and a half times"
#: as complex as a linear transform's four scalar products (no timing of it alone)
LATTICE_SHADER_COMPLEXITY = 2.5
#: the text of section 6 rounds the three ratios to 75, 80 and 77 percent
LATTICE_TEXT_PERCENT: tuple[int, int, int] = (75, 80, 77)


def lattice_ratio_range() -> tuple[float, float]:
    """Smallest and largest trilinear / linear frame rate of the GRAPP table."""
    ratios = [r.ratio for r in LATTICE_FPS]
    return min(ratios), max(ratios)


def wire_render_ratio_range() -> tuple[float, float]:
    """Smallest and largest deformed / standard render time of the wire paper."""
    ratios = [r.render_ratio for r in WIRE_TIMINGS]
    return min(ratios), max(ratios)


def fmt_ratio(x: float) -> str:
    """A ratio as the reports print it: ``2.20x``."""
    return f"{x:.2f}x"
