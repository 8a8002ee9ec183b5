"""The ``voxwarp`` command line: info, render, demo, samples, bench.

INPUT is a volume file or folder (npy, npz, raw + JSON sidecar, NRRD, NIfTI, DICOM
folder, TIFF), a scene JSON written by ``Scene.save``, or ``sample:NAME`` for a
bundled sample (``voxwarp samples`` lists them).
"""

from __future__ import annotations

import argparse
import json
import sys
import warnings
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from app.errors import VoxwarpError

MODES = ("dvr", "mip", "minip", "average", "flm", "iso")


def _size(text: str) -> tuple[int, int]:
    try:
        w, h = (int(v) for v in text.lower().split("x"))
    except ValueError as exc:
        raise argparse.ArgumentTypeError(f"size must look like 512x512; got {text!r}") from exc
    if not (1 <= w <= 16384 and 1 <= h <= 16384):
        raise argparse.ArgumentTypeError(f"size must be 1..16384 per side; got {text!r}")
    return w, h


def _view(text: str) -> Any:
    if text in ("+x", "-x", "+y", "-y", "+z", "-z"):
        return text
    try:
        az, el = (float(v) for v in text.split(","))
    except ValueError as exc:
        raise argparse.ArgumentTypeError(
            f"view must be one of +x,-x,+y,-y,+z,-z or AZIMUTH,ELEVATION degrees; got {text!r}"
        ) from exc
    return (az, el)


def _is_scene_json(path: Path) -> bool:
    if path.suffix.lower() != ".json" or not path.is_file():
        return False
    try:
        d = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return False
    return isinstance(d, dict) and d.get("format") == "voxwarp-scene"


def load_input(
    spec: str,
    *,
    spacing: Sequence[float] | None = None,
    downsample: int = 1,
    nan_policy: str = "raise",
) -> Any:
    """Load INPUT: returns a Volume, or a Scene for scene JSON."""
    from app.io import load_volume
    from app.samples import load_sample
    from app.scene import Scene

    if spec.startswith("sample:"):
        vol = load_sample(spec.split(":", 1)[1], spacing=spacing)
        return vol.downsample(downsample) if downsample > 1 else vol
    path = Path(spec)
    if _is_scene_json(path):
        return Scene.load(path)
    return load_volume(path, spacing=spacing, nan_policy=nan_policy, downsample=downsample)  # type: ignore[arg-type]


def _add_volume_args(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--spacing", nargs=3, type=float, metavar=("SX", "SY", "SZ"), help="voxel size in mm"
    )
    p.add_argument("--downsample", type=int, default=1, metavar="N", help="reduce by N per axis")
    p.add_argument(
        "--nan", choices=("raise", "mask"), default="raise", help="NaN/Inf voxels: reject or mask"
    )


def _scene_from_args(obj: Any, args: argparse.Namespace) -> Any:
    from app.scene import Scene
    from app.transfer_function import TransferFunction

    tf: Any = None
    if args.tf is not None:
        tf = TransferFunction.load(args.tf) if args.tf.endswith(".json") else args.tf
    if isinstance(obj, Scene):
        changes: dict[str, Any] = {}
        if tf is not None:
            changes["transfer_function"] = TransferFunction.coerce(tf, obj.volume)
        for key in ("mode", "projection", "view", "step", "window", "seed", "iso_value", "zoom"):
            val = getattr(args, key)
            if val is not None:
                changes[key] = val
        if args.jitter is not None:
            changes["jitter"] = args.jitter
        if args.shading is not None:
            changes["shading"] = args.shading
        if changes.keys() & {"view", "projection", "zoom"}:
            changes["camera"] = None
        return obj.copy(**changes)
    kw: dict[str, Any] = {
        "mode": args.mode or "dvr",
        "transfer_function": tf if tf is not None else "ct-bone",
        "view": args.view or "-y",
        "projection": args.projection or "perspective",
        "step": args.step if args.step is not None else 1.0,
        "window": args.window,
        "jitter": True if args.jitter is None else args.jitter,
        "seed": args.seed if args.seed is not None else 0,
        "shading": args.shading,
        "iso_value": args.iso_value,
        "zoom": args.zoom if args.zoom is not None else 1.0,
    }
    return Scene(obj, **kw)


def _tf_arg(tf: str | None) -> Any:
    from app.transfer_function import TransferFunction

    if tf is not None and tf.endswith(".json"):
        return TransferFunction.load(tf)
    return tf


def cmd_info(args: argparse.Namespace) -> int:
    """``voxwarp info INPUT``: dims, dtype, spacing, value range, histogram."""
    from app.io import volume_info, volume_summary
    from app.scene import Scene

    obj = load_input(
        args.input, spacing=args.spacing, downsample=args.downsample, nan_policy=args.nan
    )
    vol = obj.volume if isinstance(obj, Scene) else obj
    if args.json:
        print(json.dumps(volume_info(vol), indent=2))
    else:
        print(volume_summary(vol))
    return 0


def cmd_render(args: argparse.Namespace) -> int:
    """``voxwarp render INPUT -o out.png``: render one image headless."""
    from app.image_io import write_image
    from app.render import OffscreenRenderer

    obj = load_input(
        args.input, spacing=args.spacing, downsample=args.downsample, nan_policy=args.nan
    )
    scene = _scene_from_args(obj, args)
    out = Path(args.output)
    dtype = "f4" if out.suffix.lower() in (".exr", ".hdr") else "u1"
    with OffscreenRenderer(*args.size, dtype=dtype) as r:
        img = r.render(scene)
    write_image(out, img)
    if args.save_scene:
        scene.save(args.save_scene)
        print(f"scene: {args.save_scene}")
    print(out)
    return 0


def cmd_demo(args: argparse.Namespace) -> int:
    """``voxwarp demo``: render the default sample in every mode into a folder."""
    from app.image_io import write_image
    from app.render import OffscreenRenderer
    from app.samples import DEFAULT_SAMPLE, suggested_transfer_function
    from app.scene import Scene

    spec = args.input or f"sample:{DEFAULT_SAMPLE}"
    obj = load_input(spec)
    vol = obj.volume if isinstance(obj, Scene) else obj
    out = Path(args.out)
    tf = _tf_arg(args.tf)
    if tf is None:
        tf = suggested_transfer_function(vol.name) if spec.startswith("sample:") else "ct-bone"
    paths = []
    with OffscreenRenderer(*args.size) as r:
        for mode in MODES:
            scene = Scene(vol, mode=mode, transfer_function=tf, view=args.view, zoom=1.3)
            img = r.render(scene)
            paths.append(write_image(out / f"{vol.name}_{mode}.png", img))
        scene.save(out / f"{vol.name}_scene.json")
    for p in paths:
        print(p)
    return 0


def cmd_samples(args: argparse.Namespace) -> int:
    """``voxwarp samples``: list bundled samples."""
    from app.samples import sample_names

    for name in sample_names():
        print(f"sample:{name}")
    return 0


def cmd_bench(args: argparse.Namespace) -> int:
    """``voxwarp bench render``: timings against references (see app.bench)."""
    from app.bench import bench_render
    from app.files import atomic_write_text

    vol = None
    if args.input:
        obj = load_input(args.input)
        vol = getattr(obj, "volume", obj)
    report = bench_render(
        vol,
        size=args.size,
        frames=args.frames,
        warmup=args.warmup,
        use_vtk=not args.no_vtk,
        step=args.step,
        transfer_function=_tf_arg(args.tf),
        log=lambda s: print(s, file=sys.stderr),
    )
    command = (
        "voxwarp " + " ".join(sys.argv[1:])
        if sys.argv[0].endswith("voxwarp")
        else ("voxwarp bench render")
    )
    text = report.markdown(command)
    print(text)
    for mode in ("dvr", "mip"):
        ratio = report.ratio("VTK fixed-point (CPU)", mode)
        if ratio is not None:
            print(f"{mode}: voxwarp is {ratio:.2f}x the speed of VTK's fixed-point raycaster")
    if args.markdown:
        atomic_write_text(Path(args.markdown), text)
    return 0


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of the ``voxwarp`` command."""
    p = argparse.ArgumentParser(prog="voxwarp", description=__doc__.split("\n")[0])
    sub = p.add_subparsers(dest="command", required=True)

    pi = sub.add_parser("info", help="print dims, dtype, spacing, value range, histogram")
    pi.add_argument("input")
    pi.add_argument("--json", action="store_true", help="machine-readable output")
    _add_volume_args(pi)
    pi.set_defaults(func=cmd_info)

    pr = sub.add_parser("render", help="render INPUT (volume or scene JSON) to an image")
    pr.add_argument("input")
    pr.add_argument("-o", "--output", default="out.png", help="PNG/EXR/TIFF by extension")
    pr.add_argument("--mode", choices=MODES)
    pr.add_argument("--projection", choices=("perspective", "orthographic"))
    pr.add_argument("--view", type=_view, help="+x,-x,+y,-y,+z,-z or AZIMUTH,ELEVATION")
    pr.add_argument("--size", type=_size, default=(512, 512), help="WxH pixels")
    pr.add_argument("--tf", help="preset name or transfer function JSON file")
    pr.add_argument("--step", type=float, help="sample distance in voxels (default 1)")
    pr.add_argument("--window", nargs=2, type=float, metavar=("LEVEL", "WIDTH"))
    pr.add_argument("--iso", dest="iso_value", type=float, help="isovalue for --mode iso")
    pr.add_argument("--zoom", type=float)
    pr.add_argument("--seed", type=int, help="jitter seed")
    pr.add_argument("--jitter", action=argparse.BooleanOptionalAction, default=None)
    pr.add_argument("--shading", action=argparse.BooleanOptionalAction, default=None)
    pr.add_argument("--save-scene", metavar="JSON", help="also write the scene JSON")
    _add_volume_args(pr)
    pr.set_defaults(func=cmd_render)

    pd = sub.add_parser("demo", help="render a sample in every mode into a folder")
    pd.add_argument("input", nargs="?", help="volume (default: the bundled real CT)")
    pd.add_argument("--out", default="out")
    pd.add_argument("--size", type=_size, default=(512, 512))
    pd.add_argument("--tf", help="preset or tf.json (default: suits the sample)")
    pd.add_argument("--view", type=_view, default="-y")
    pd.set_defaults(func=cmd_demo)

    ps = sub.add_parser("samples", help="list bundled sample volumes")
    ps.set_defaults(func=cmd_samples)

    pb = sub.add_parser("bench", help="benchmarks")
    bsub = pb.add_subparsers(dest="bench", required=True)
    pbr = bsub.add_parser("render", help="raycaster timings vs VTK and no-skipping")
    pbr.add_argument("input", nargs="?", help="volume (default: real CT upsampled to 256³)")
    pbr.add_argument("--size", type=_size, default=(512, 512))
    pbr.add_argument("--frames", type=int, default=10)
    pbr.add_argument("--warmup", type=int, default=2)
    pbr.add_argument("--step", type=float, default=1.0)
    pbr.add_argument("--tf", help="preset or tf.json (default: suits the bench volume)")
    pbr.add_argument("--no-vtk", action="store_true", help="skip the VTK references")
    pbr.add_argument("--markdown", metavar="FILE", help="also write the table to FILE")
    pbr.set_defaults(func=cmd_bench)
    return p


def _join_negative_views(argv: list[str]) -> list[str]:
    # "--view -y" / "--view -30,20": argparse would take the value for an option
    out: list[str] = []
    i = 0
    while i < len(argv):
        if argv[i] == "--view" and i + 1 < len(argv) and argv[i + 1].startswith("-"):
            out.append(f"--view={argv[i + 1]}")
            i += 2
            continue
        out.append(argv[i])
        i += 1
    return out


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``voxwarp`` console script."""
    parser = build_parser()
    args = parser.parse_args(_join_negative_views(list(sys.argv[1:] if argv is None else argv)))
    with warnings.catch_warnings():
        warnings.simplefilter("default")
        old_format = warnings.formatwarning
        warnings.formatwarning = lambda msg, cat, *a, **k: f"voxwarp: warning: {msg}\n"
        try:
            return int(args.func(args) or 0)
        except VoxwarpError as exc:
            print(f"voxwarp: error: {exc}", file=sys.stderr)
            return 2
        except KeyboardInterrupt:
            return 130
        finally:
            warnings.formatwarning = old_format


if __name__ == "__main__":
    sys.exit(main())
