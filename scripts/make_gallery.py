"""Write the documentation gallery and the README's top images from voxwarp commands.

Each entry of :data:`GALLERY` (and of :data:`FIGURES`, the concept pages' figures,
written to ``docs/figures/``) is one or more ``voxwarp`` command lines (run in the
repository root with this Python's ``voxwarp``, as a user would type them) and the image
the last one writes under ``out/gallery/``. The image is downsized to a small palette PNG
in ``docs/gallery/NAME.png``; ``docs/gallery.md`` shows each with its caption and the
exact commands; entries with a ``readme`` title also become ``docs/images/readme_NAME.png``
(the README's top row). Usage::

    .venv/bin/python scripts/make_gallery.py             # every entry (a few minutes)
    .venv/bin/python scripts/make_gallery.py stent_dvr   # only these entries

The window screenshot needs an X display; without one the command runs under
``xvfb-run -a``. ``tests/test_docs.py`` checks that the page matches this list and that
every command parses.
"""

from __future__ import annotations

import argparse
import os
import re
import shlex
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
WORK = "out/gallery"  # where the commands write (git-ignored)
GALLERY_DIR = ROOT / "docs" / "gallery"
FIGURE_DIR = ROOT / "docs" / "figures"
README_DIR = ROOT / "docs" / "images"
PAGE = ROOT / "docs" / "gallery.md"
MAX_BYTES = 60_000  # per gallery PNG
README_HEIGHT = 200  # px: the README's top images share one height


@dataclass(frozen=True)
class Entry:
    """One gallery image: the commands that make it and what it shows."""

    name: str  #: docs/gallery/NAME.png
    title: str
    caption: str  #: one sentence
    commands: tuple[str, ...]  #: voxwarp command lines, run in order from the repository root
    image: str  #: the file the last command writes (repository-relative)
    width: int = 480  #: the gallery copy's width in pixels
    readme: str = ""  #: alt text of the README's copy; empty: not in the README
    #: palette: median cut keeps smooth greys; octree keeps a screenshot's few saturated colours
    octree: bool = False

    def argvs(self) -> list[list[str]]:
        """Each command as the argument list after ``voxwarp``."""
        out = []
        for line in self.commands:
            words = shlex.split(line)
            assert words[0] == "voxwarp", line
            out.append(words[1:])
        return out


def _out(name: str) -> str:
    return f"{WORK}/{name}"


STENT_MS = (
    "voxwarp render sample:stent --tf hot --size 320x480 --massspring 8"
    " --drag-at 75,64,150:35,0,0 --drag-at 75,64,118:35,0,0 --settle -o " + _out("stent_ms.png")
)

GALLERY: tuple[Entry, ...] = (
    Entry(
        "stent_dvr",
        "A real CT, direct volume rendering",
        "The bundled CT of a stented aorta (visvis), emission-absorption raycasting with the"
        " `hot` transfer function.",
        ("voxwarp render sample:stent --tf hot --size 320x480 -o " + _out("stent_dvr.png"),),
        _out("stent_dvr.png"),
        width=320,
        readme="The bundled stent CT, direct volume rendering",
    ),
    Entry(
        "stent_mip",
        "The same CT as a maximum intensity projection",
        "MIP with the window chosen from the data's percentiles (the stent wires and the"
        " contrast-filled vessels are the brightest voxels).",
        ("voxwarp render sample:stent --mode mip --size 320x480 -o " + _out("stent_mip.png"),),
        _out("stent_mip.png"),
        width=320,
    ),
    Entry(
        "stent_massspring",
        "Mass-spring: pushing the aorta sideways",
        "Two elements of an 8x8x8 mass-spring grid are held 35 mm to the side and the springs"
        " pull their neighbours along; the CT is rendered through the settled offset field,"
        " never resampled.",
        (STENT_MS,),
        _out("stent_ms.png"),
        width=320,
        readme="The stent CT pushed sideways by a mass-spring model",
    ),
    Entry(
        "stent_chainmail",
        "3D ChainMail: one drag, settled at once",
        "One element dragged 30 mm; ChainMail moves every other element only as far as the"
        " links' slack requires, then four relaxation steps round the kinks. Only the 8"
        " corners are fixed (--anchor corners, ChainMail's default): a fixed shell would"
        " hold a 30 mm drag on this coarse grid back to 46 %.",
        (
            "voxwarp render sample:stent --tf hot --size 320x480 --chainmail 8 --anchor corners"
            " --drag-at 75,64,128:30,0,0 --relax 4 -o " + _out("stent_cm.png"),
        ),
        _out("stent_cm.png"),
        width=320,
    ),
    Entry(
        "fish_wires",
        "Wires: bending a spine",
        "A wire laid along the fish phantom's spine and a bent copy of it: the body is swept"
        " from one to the other and its tail turned 90 degrees (the wire paper's Figure 2);"
        " the faint seam behind the head is where the wire starts inside the body and the"
        " paper's rigid sweep cuts it (voxwarp warns).",
        (
            "voxwarp render sample:fish --view +z --tf ct-soft --zoom 1.5 --size 480x360"
            " --wires sample:fish_spine_wires -o " + _out("fish_wires.png"),
        ),
        _out("fish_wires.png"),
        readme="The fish phantom bent and twisted by a wire",
    ),
    Entry(
        "fish_lattice",
        "A trilinear lattice over a volume",
        "The fish rendered through the inverse of a lattice of trilinear cells (Newton steps"
        " per ray sample, seeded by a baked inverse).",
        (
            "voxwarp render sample:fish --view +z --tf ct-soft --zoom 1.4 --size 480x360"
            " --lattice sample:fish_lattice_bend -o " + _out("fish_lattice.png"),
        ),
        _out("fish_lattice.png"),
    ),
    Entry(
        "lattice_meshes",
        "Trilinear lattices on meshes",
        "Tubes wrapped round a torus by one lattice and staying in contact (the GRAPP 2010"
        " paper's Figure 1), deformed in the vertex shader.",
        (
            "voxwarp render sample:lattice_torus_tubes --size 480x360 --zoom 1.6 -o "
            + _out("lattice_tubes.png"),
        ),
        _out("lattice_tubes.png"),
    ),
    Entry(
        "colin27_dvr",
        "A real MRI, cut open",
        "The Colin27 head MRI seen from the patient's right with the right half clipped away"
        " (world mm, patient RAS+) and the orientation marker on.",
        (
            "voxwarp render sample:colin27 --view right --clip -90,2,-130,92,-75,110"
            " --zoom 1.3 --size 400x360 --marker -o " + _out("colin27_dvr.png"),
        ),
        _out("colin27_dvr.png"),
        width=400,
        readme="The Colin27 MRI, cut open at the midline",
    ),
    Entry(
        "colin27_slice",
        "A deformed slice: rest and deformed as a checkerboard",
        "A coronal slice of Colin27 sampled through a mass-spring push, the squares"
        " alternating between the rest and the deformed state.",
        (
            "voxwarp slice sample:colin27 --plane coronal --at -16 --pixel 0.75 --massspring 8"
            " --drag-at 30,-16,40:0,0,-20 --settle --show checkerboard -o "
            + _out("colin27_slice.png"),
        ),
        _out("colin27_slice.png"),
        width=260,
    ),
    Entry(
        "stent_flm",
        "First local maximum with a threshold from the histogram",
        "FLM on the stent CT: the threshold comes from the histogram's object/background"
        " split (printed on stderr), so the background's noise no longer counts as a"
        " maximum and draws a flat grey box.",
        ("voxwarp render sample:stent --mode flm --size 320x480 -o " + _out("stent_flm.png"),),
        _out("stent_flm.png"),
        width=320,
    ),
    Entry(
        "window_2x2",
        "The desktop window: three slices and 3D",
        "The window's 2x2 layout on the stent CT bent by the wire `voxwarp demo` lays along"
        " it: axial, sagittal and coronal slices through the same warp as the 3D view.",
        (
            f"voxwarp demo sample:stent --size 320x400 -o {WORK}/demo",
            f"voxwarp gui {WORK}/demo/stent_wires_scene.json --size 1100x750"
            f" --screenshot {WORK}/window_2x2.png",
        ),
        _out("window_2x2.png"),
        width=720,
        octree=True,
    ),
    Entry(
        "registration",
        "Viewing a registration without resampling",
        "Colin27 deformed by known bumps, registered back with SimpleITK demons, and the"
        " moving image rendered through the recovered displacement field.",
        (f"voxwarp demo registration -o {WORK}",),
        _out("registration.png"),
        width=720,
    ),
    Entry(
        "demo_massspring",
        "Teaching: explicit vs semi-implicit Euler",
        "The mass-spring demo's figure sheet: energy and stability of both integrators, and"
        " renders of the fish bent by the same drag.",
        (f"voxwarp demo massspring -o {WORK}",),
        _out("massspring.png"),
        width=720,
    ),
    Entry(
        "demo_chainmail",
        "Teaching: how ChainMail propagates a drag",
        "The ChainMail demo's figure sheet: the order in which one drag moves the elements"
        " and the effect of 0, 1 and 4 relaxation steps.",
        (f"voxwarp demo chainmail -o {WORK}",),
        _out("chainmail.png"),
        width=720,
    ),
    Entry(
        "demo_wires",
        "Teaching: wire field resolution and cost",
        "The wire demo's figure sheet: the attribute field from 1:1 to 1:4096 (the wire"
        " paper's Figure 12), the ray samples it ignores and the cost of rendering through it.",
        (f"voxwarp demo wires -o {WORK}",),
        _out("wires.png"),
        width=720,
    ),
    Entry(
        "demo_lattice",
        "Teaching: trilinear lattices",
        "The lattice demo's figure sheet: what a lattice can do that a matrix cannot (a bent"
        " volume, tubes wrapped round a torus) and the two ways of carrying normals.",
        (f"voxwarp demo lattice -o {WORK}",),
        _out("lattice.png"),
        width=720,
    ),
)

#: the concept pages' figures (docs/figures/NAME.png; each page's caption gives the
#: command): before/after pairs of the tissue-like defaults, not on the gallery page
FIGURES: tuple[Entry, ...] = (
    Entry(
        "nose_push_corners",
        "Boundary conditions: the thesis's corners",
        "A 15 mm push on the face of the Colin27 MRI (mass-spring, 16^3 elements, settled)"
        " with only the 8 grid corners fixed, shown as rest (blue) against deformed (red):"
        " the springs carry the push through the whole head, and the occiput moves as much"
        " as the face.",
        (
            "voxwarp slice sample:colin27 --plane sagittal --at 0 --pixel 1 --massspring 16"
            " --anchor corners --drag-at 0,89.5,-1.5:0,-15,0 --settle --show difference -o "
            + _out("nose_corners.png"),
        ),
        _out("nose_corners.png"),
        width=260,
    ),
    Entry(
        "nose_push_default",
        "Boundary conditions: the default",
        "The same push with the defaults: the grid's outer shell is fixed, elements beyond"
        " the region of influence (here 66 mm) are anchored and the grid reaches 15 mm past"
        " the volume: only the face moves.",
        (
            "voxwarp slice sample:colin27 --plane sagittal --at 0 --pixel 1 --massspring 16"
            " --drag-at 0,89.5,-1.5:0,-15,0 --settle --show difference -o "
            + _out("nose_default.png"),
        ),
        _out("nose_default.png"),
        width=260,
    ),
    Entry(
        "push_margin0",
        "A push through the box, without a margin",
        "ChainMail pulls the vertex of the head 15 mm up on a grid that ends at the"
        " volume's box (--grid-margin 0): the warp is the identity outside the box, so the"
        " skull is flattened against its top.",
        (
            "voxwarp slice sample:colin27 --plane coronal --at -20 --pixel 1 --chainmail 16"
            " --drag-at 0,-20,100:0,0,15 --grid-margin 0 -o " + _out("push_margin0.png"),
        ),
        _out("push_margin0.png"),
        width=260,
    ),
    Entry(
        "push_margin",
        "A push through the box, with the default margin",
        "The same drag with the default margin (the largest drag, 15 mm): the grid reaches"
        " beyond the box, the skull is carried out of it and the slice grows to show it.",
        (
            "voxwarp slice sample:colin27 --plane coronal --at -20 --pixel 1 --chainmail 16"
            " --drag-at 0,-20,100:0,0,15 -o " + _out("push_margin.png"),
        ),
        _out("push_margin.png"),
        width=260,
    ),
    Entry(
        "wire_rigid_sides",
        "Wire sides: the paper's rigid sweep",
        "A wire bends the midline of Colin27 15 mm (radius 35 mm) with the paper's sweep"
        " (--sides rigid): the masked cross-sections move and their old place is vacated,"
        " which on anatomy reads as a black hole and a straight tear.",
        (
            "voxwarp slice sample:colin27 --plane coronal --at -20 --pixel 1 --wires"
            " sample:colin27_midline_wires --sides rigid -o " + _out("wire_rigid.png"),
        ),
        _out("wire_rigid.png"),
        width=260,
    ),
    Entry(
        "wire_smooth_sides",
        "Wire sides: smooth, the default",
        "The same wire with smooth sides: everything within the radius moves and the"
        " surrounding tissue stretches over the side falloff (here 39.6 mm), so nothing is"
        " left empty and nothing tears.",
        (
            "voxwarp slice sample:colin27 --plane coronal --at -20 --pixel 1 --wires"
            " sample:colin27_midline_wires -o " + _out("wire_smooth.png"),
        ),
        _out("wire_smooth.png"),
        width=260,
    ),
    Entry(
        "registration_grid_glyphs",
        "A registration's warped grid and displacement glyphs",
        "The demons registration of the bundled MRI (voxwarp demo registration --quick)"
        " seen on an axial slice through its field: the moving image's grid (yellow, every"
        " 10 mm) bent by the chain, and arrows of u = chain(x) - x with the legend in mm.",
        (
            "voxwarp demo registration --quick -o " + WORK,
            "voxwarp slice "
            + _out("registration_moving.nii.gz")
            + " --displacement "
            + _out("registration_field.h5")
            + " --overlay grid,glyphs --pixel 0.5 -o "
            + _out("registration_grid.png"),
        ),
        _out("registration_grid.png"),
        width=300,
    ),
)


def shell_lines(command: str, width: int = 76) -> str:
    """``command`` broken before its options into lines of at most ``width`` characters
    (where an option and its values fit), continued with a backslash as a shell reads them."""
    groups: list[str] = []
    for word in command.split(" "):
        starts_option = word.startswith("-") and not re.match(r"-[\d.]", word)
        if groups and not starts_option:
            groups[-1] += f" {word}"
        else:
            groups.append(word)
    lines, line = [], ""
    for group in groups:
        if line and len(line) + 1 + len(group) > width - 2:
            lines.append(line)
            line = "    " + group
        else:
            line = f"{line} {group}" if line else group
    return " \\\n".join([*lines, line])


def page(entries: tuple[Entry, ...] = GALLERY) -> str:
    """The Markdown of docs/gallery.md for ``entries``."""
    parts = [
        "# Gallery\n",
        "Every picture below was made by the `voxwarp` commands under it, run from the"
        " repository root; `scripts/make_gallery.py` runs them all again, writes these"
        " small copies and this page (`.venv/bin/python scripts/make_gallery.py`, a few"
        " minutes on two cores). The full-size images are in `out/gallery/`.\n",
    ]
    for e in entries:
        cmds = "\n".join(shell_lines(c) for c in e.commands)
        parts.append(
            f"## {e.title}\n\n![{e.title}](gallery/{e.name}.png)\n\n{e.caption}\n\n"
            f"```sh\n{cmds}\n```\n"
        )
    return "\n".join(parts)


def _needs_display(argv: list[str]) -> bool:
    return argv[0] == "gui" and not os.environ.get("DISPLAY")


def run(entry: Entry) -> float:
    """Run ``entry``'s commands; returns the seconds they took."""
    exe = Path(sys.executable).with_name("voxwarp")
    start = time.perf_counter()
    for argv in entry.argvs():
        cmd = [str(exe), *argv]
        if _needs_display(argv):
            cmd = ["xvfb-run", "-a", *cmd]
        print("$", shlex.join(["voxwarp", *argv]), flush=True)
        subprocess.run(cmd, cwd=ROOT, check=True)
    return time.perf_counter() - start


def small_png(
    src: Path, dest: Path, width: int, max_bytes: int = MAX_BYTES, octree: bool = False
) -> int:
    """Downsize ``src`` to ``width`` pixels into a palette PNG at ``dest``; returns bytes."""
    from PIL import Image

    img = Image.open(src).convert("RGB")
    if img.width > width:
        img = img.resize((width, round(img.height * width / img.width)), Image.LANCZOS)
    for colours in (256, 128, 64, 32):
        method = Image.Quantize.FASTOCTREE if octree else Image.Quantize.MEDIANCUT
        small = img.quantize(colors=colours, method=method, dither=0)
        tmp = dest.with_suffix(".tmp.png")
        small.save(tmp, optimize=True)
        if tmp.stat().st_size <= max_bytes or colours == 32:
            break
    tmp.replace(dest)
    return dest.stat().st_size


def main(argv: list[str] | None = None) -> int:
    """Run the chosen entries (default all), then write the page."""
    from PIL import Image

    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("names", nargs="*", help="entries to rerun (default: all)")
    p.add_argument(
        "--reuse", action="store_true", help="keep images already in out/gallery (only resize)"
    )
    args = p.parse_args(argv)
    chosen = [e for e in (*GALLERY, *FIGURES) if not args.names or e.name in args.names]
    (ROOT / WORK).mkdir(parents=True, exist_ok=True)
    GALLERY_DIR.mkdir(parents=True, exist_ok=True)
    FIGURE_DIR.mkdir(parents=True, exist_ok=True)
    for e in chosen:
        seconds = 0.0 if args.reuse and (ROOT / e.image).is_file() else run(e)
        dest = (FIGURE_DIR if e in FIGURES else GALLERY_DIR) / f"{e.name}.png"
        size = small_png(ROOT / e.image, dest, e.width, octree=e.octree)
        print(f"{e.name}: {seconds:.1f} s, {size / 1000:.0f} kB", flush=True)
        if e.readme:
            with Image.open(ROOT / e.image) as img:
                width = round(img.width * README_HEIGHT / img.height)
            small_png(ROOT / e.image, README_DIR / f"readme_{e.name}.png", width, 40_000)
    PAGE.write_text(page(), encoding="utf-8")
    return 0


if __name__ == "__main__":
    sys.exit(main())
