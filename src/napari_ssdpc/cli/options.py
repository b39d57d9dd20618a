"""Command-line options built from the settings models: one place for names, choices and defaults.

Each option of ``ssdpc reconstruct`` that sets a reconstruction setting takes its type, its
choices, its help text and its default from the field of
:class:`~napari_ssdpc.settings.ReconstructionSettings`, so the CLI never types them again.
"""

from __future__ import annotations

import argparse
import typing

from napari_ssdpc.settings import ReconstructionSettings, RunConfig
from napari_ssdpc.settings.optics import Optics

__all__ = ["FLAGS", "add_reconstruction_options", "run_config"]

#: CLI flag -> settings field (``--z`` sets the pair z_min_um, z_max_um).
FLAGS = {
    "dz": "dz_um",
    "method": "method",
    "model": "model",
    "iterations": "rl_iterations",
    "alpha": "tikhonov_alpha",
    "sign": "sign",
    "dn-max": "dn_max",
    "tv-lambda": "tv_lambda",
    "tv-iterations": "tv_iterations",
    "refraction-increment": "refraction_increment_um3_pg",
    "device": "device",
}


def _dest(flag: str) -> str:
    """The argparse attribute of ``--flag`` ('dn-max' -> 'dn_max')."""
    return flag.replace("-", "_")


def _help(field: str) -> str:
    info = ReconstructionSettings.model_fields[field]
    default = info.default
    shown = "the method's default" if default is None else default
    return f"{info.description} (default {shown})"


def add_reconstruction_options(parser: argparse.ArgumentParser) -> None:
    """Add --config, --z and one flag per reconstruction setting (see :data:`FLAGS`).

    Parameters
    ----------
    parser : argparse.ArgumentParser
        The ``reconstruct`` (or ``bench``) sub-command's parser; choices, defaults and help come
        from :class:`~napari_ssdpc.settings.reconstruction.ReconstructionSettings`.
    """
    fields = ReconstructionSettings.model_fields
    parser.add_argument(
        "--config", help="run configuration YAML (optics + reconstruction sections), e.g. saved by napari"
    )
    parser.add_argument(
        "--z",
        type=float,
        nargs=2,
        metavar=("ZMIN", "ZMAX"),
        help=f"z range in µm, z > 0 farther from the objective (default {fields['z_min_um'].default:g} "
        f"{fields['z_max_um'].default:g}), e.g. --z -40 40 or --z -1e2 1e2",
    )
    for flag, name in FLAGS.items():
        ann = fields[name].annotation
        choices = typing.get_args(ann) if typing.get_origin(ann) is typing.Literal else None
        kind = int if ann is int else (str if choices else float)
        parser.add_argument(f"--{flag}", type=kind, choices=choices, help=_help(name))


def run_config(args: argparse.Namespace, optics: Optics | None) -> RunConfig:
    """The run configuration: the --config file (or defaults), then the flags given on top.

    Parameters
    ----------
    args : argparse.Namespace
        Parsed arguments with the options of :func:`add_reconstruction_options`.
    optics : Optics or None
        Optics to use (from --optics or the calibration); None keeps the config's.

    Returns
    -------
    RunConfig
    """
    cfg = RunConfig.from_yaml(args.config) if getattr(args, "config", None) else RunConfig()
    given = {name: getattr(args, _dest(flag), None) for flag, name in FLAGS.items()}
    changes = {name: value for name, value in given.items() if value is not None}
    if getattr(args, "z", None) is not None:
        changes.update(z_min_um=float(args.z[0]), z_max_um=float(args.z[1]))
    rec = ReconstructionSettings.from_dict({**cfg.reconstruction.to_dict(), **changes}, source="command line")
    return RunConfig(optics=optics or cfg.optics, reconstruction=rec)
