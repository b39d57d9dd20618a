"""``ssdpc dpc``: phase (2D) or refractive index (3D) from a conventional DPC stack (an LED array or a
segmented condenser, one half of the illumination disk per image; docs/dpc.md)."""

from __future__ import annotations

__all__ = ["add_dpc_command", "cmd_dpc"]


def add_dpc_command(sub) -> None:
    """Add ``dpc`` to the subcommands of ``ssdpc``.

    Parameters
    ----------
    sub : argparse._SubParsersAction
        The subparsers of the ``ssdpc`` parser.
    """
    from napari_ssdpc.reconstruction.led_dpc import DPC_METHODS

    s = sub.add_parser(
        "dpc",
        help="phase (2D) or refractive index (3D) from an LED-array or segmented-condenser DPC stack",
        description="One image per half-disk pattern (2D: the phase, rad), or a z-stack per pattern (3D: the "
        "refractive index), through the same phase methods as the light-field frames. The optics file gives "
        "the patterns' directions (patterns_deg) and, for a z-stack, its focal planes (z_um): docs/dpc.md.",
    )
    s.add_argument("stack", help="TIFF of the images: (patterns, y, x), or (patterns, planes, y, x) for a z-stack")
    s.add_argument("--optics", required=True, help="DPC optics file (YAML; docs/dpc.md)")
    s.add_argument("-o", "--output", required=True, help="OUT.ome.tif: the phase (2D, rad) or the RI (3D)")
    s.add_argument(
        "--method",
        choices=tuple(DPC_METHODS),
        default="tikhonov",
        help="tikhonov: linear and fast; tv: total variation with the sign of Δn; multislice (z-stacks): tv refined "
        "with a multislice model of the images, for strong objects (default %(default)s)",
    )
    s.add_argument(
        "--alpha",
        type=float,
        help="Tikhonov regularisation, relative to the strongest frequency's Σ|H|² per image (default 0.015)",
    )
    s.add_argument(
        "--sign",
        choices=("auto", "denser", "lighter", "any"),
        help="tv: the sign of Δn against the medium (default: any for 2D, auto for a z-stack)",
    )
    s.add_argument("--iterations", type=int, help="tv: most iterations (default 60, 200 for a z-stack)")
    s.add_argument("--z-min-um", type=float, help="3D: first plane, µm (default: the stack's first focal plane)")
    s.add_argument("--z-max-um", type=float, help="3D: last plane, µm (default: the stack's last focal plane)")
    s.add_argument("--dz-um", type=float, help="3D: plane spacing, µm (default: the stack's own spacing)")
    s.add_argument("--overwrite", action="store_true", help="replace an output napari-ssdpc did not write")
    s.set_defaults(func=cmd_dpc)


def cmd_dpc(args) -> None:
    """Reconstruct the stack and write the result.

    Parameters
    ----------
    args : argparse.Namespace
        The parsed options of `ssdpc dpc` (see ``ssdpc dpc --help``).
    """
    from napari_ssdpc.io.frames import read_stack, write_ome_tiff
    from napari_ssdpc.io.paths import check_outputs
    from napari_ssdpc.progress import tqdm_callback
    from napari_ssdpc.reconstruction.led_dpc import dpc_settings, reconstruct_dpc, settings_for
    from napari_ssdpc.reconstruction.led_views import LedViews
    from napari_ssdpc.settings.dpc_optics import DpcOptics

    optics = DpcOptics.from_yaml(args.optics)
    out = check_outputs(
        {"output": args.output}, {"stack": args.stack, "optics file": args.optics}, overwrite=args.overwrite
    )
    stack = read_stack(args.stack, name="DPC stack")
    settings = dpc_settings(optics, alpha=args.alpha, sign=args.sign, iterations=args.iterations)
    z = {"z_min_um": args.z_min_um, "z_max_um": args.z_max_um, "dz_um": args.dz_um}
    settings_for(optics, args.method, settings, **z)  # refused before any progress is shown
    if stack.ndim >= 3:
        LedViews(optics, stack.shape[-2:]).check(stack)
    with tqdm_callback("dpc", unit="step") as cb:
        r = reconstruct_dpc(stack, optics, args.method, settings=settings, progress=cb, **z)
    meta = {"source": str(args.stack), "optics": optics.to_dict(), "medium_index": optics.medium_index}
    meta |= {"method": args.method, "settings": r.report}
    if r.phase is not None:
        path = write_ome_tiff(
            out["output"],
            r.phase,
            axes="YX",
            voxel_um=(r.pixel_um, r.pixel_um),
            description=meta | {"quantity": "phase", "unit": "rad"},
        )
        print(f"wrote {path}: phase {r.phase.min():+.3f} .. {r.phase.max():+.3f} rad, {r.pixel_um:.4f} µm pixels")
        return
    assert r.delta_n is not None
    ri = optics.medium_index + r.delta_n
    path = write_ome_tiff(
        out["output"],
        ri,
        axes="ZYX",
        voxel_um=(r.dz_um, r.pixel_um, r.pixel_um),
        description=meta | {"quantity": "refractive index", "z_um": [float(z) for z in r.z_um]},
    )
    print(
        f"wrote {path}: RI {ri.min():.4f} .. {ri.max():.4f} on {len(r.z_um)} planes "
        f"(z {r.z_um[0]:g} .. {r.z_um[-1]:g} µm), {r.pixel_um:.4f} µm pixels"
    )
