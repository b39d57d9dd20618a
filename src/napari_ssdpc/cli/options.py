"""Command-line options built from the settings models: one place for names, choices and defaults.

Each option of ``ssdpc reconstruct`` that sets a reconstruction setting takes its type, its
choices, its help text and its default from the field of
:class:`~napari_ssdpc.settings.reconstruction.ReconstructionSettings` (or of a method's section),
and the methods' descriptions from the registry, so the CLI never types them again.
"""

from __future__ import annotations

import argparse
import typing

from pydantic import BaseModel

from napari_ssdpc.reconstruction.methods import METHODS
from napari_ssdpc.settings.config import RunConfig
from napari_ssdpc.settings.optics import Optics
from napari_ssdpc.settings.outputs import SAVE_CHOICES, OutputSettings
from napari_ssdpc.settings.reconstruction import DEFAULT_Z_UM, ReconstructionSettings, merge_settings

__all__ = ["FLAGS", "add_reconstruction_options", "config_from_args"]

#: The short flags: CLI flag -> settings key; "section.key" for a method's section (``--z`` sets the
#: pair z_min_um, z_max_um; ``--alpha`` the chosen method's alpha; ``--save`` the outputs).
_NAMED = {
    "dz": "dz_um",
    "method": "method",
    "model": "rl.model",
    "iterations": "rl.iterations",
    "alpha": "*.alpha",
    "sign": "tv.sign",
    "dn-max": "tv.dn_max",
    "tv-lambda": "tv.lambda_scale",
    "tv-iterations": "tv.iterations",
    "tv-warm-iterations": "tv.warm_iterations",
    "temporal-weight": "tv.temporal_weight",
    "warm-start": "warm_start",
    "refraction-increment": "refraction_increment_um3_pg",
    "device": "device",
}


#: Keys reached by an option of their own shape (``--roi XMIN XMAX YMIN YMAX``).
_OWN_OPTION = {"multislice.roi_um"}


def _section_flags(named: dict) -> dict:
    """``--section-key`` for every key of every method's section that no short flag reaches
    (``--multislice-iterations``, ``--wotf-alpha``, ...): generated from the settings models."""
    out = {}
    for section, info in ReconstructionSettings.model_fields.items():
        model = info.annotation
        if not (isinstance(model, type) and issubclass(model, BaseModel)):
            continue
        for key in model.model_fields:
            full = f"{section}.{key}"
            if full not in named.values() and full not in _OWN_OPTION:
                out[f"{section}-{key.replace('_', '-')}"] = full
    return out


#: CLI flag -> settings key: the short flags, then one per remaining key of every method's section.
FLAGS = {**_NAMED, **_section_flags(_NAMED)}


def _dest(flag: str) -> str:
    """The argparse attribute of ``--flag`` ('dn-max' -> 'dn_max')."""
    return flag.replace("-", "_")


def _field(key: str):
    """The pydantic field behind a settings key ('*' : the default method's section)."""
    section, _, name = key.rpartition(".")
    model: type[BaseModel] = ReconstructionSettings
    if section:
        section = ReconstructionSettings().method if section == "*" else section
        model = typing.cast(type[BaseModel], ReconstructionSettings.model_fields[section].annotation)
    return model.model_fields[name]


def _help(key: str) -> str:
    info = _field(key)
    if key == "*.alpha":
        return "Tikhonov regularisation of the chosen method (default: the method's, tv/wotf 0.1, rl 0.01)"
    method = key.split(".")[0] if "." in key else ""
    where = f" ('{method}')" if method else ""
    return f"{info.description}{where} (default {info.default})"


def add_reconstruction_options(parser: argparse.ArgumentParser) -> None:
    """Add --config, --z and one flag per reconstruction setting (see :data:`FLAGS`).

    Parameters
    ----------
    parser : argparse.ArgumentParser
        The ``reconstruct`` sub-command's parser; choices, defaults and help come from
        :class:`~napari_ssdpc.settings.reconstruction.ReconstructionSettings` and the method
        registry.
    """
    parser.add_argument(
        "--config", help="run configuration YAML (optics, reconstruction and outputs sections), e.g. saved by napari"
    )
    z0, z1 = DEFAULT_Z_UM
    parser.add_argument(
        "--z",
        type=float,
        nargs=2,
        metavar=("ZMIN", "ZMAX"),
        help=f"z range in µm, z > 0 farther from the objective (default {z0:g} {z1:g}), e.g. --z -40 40",
    )
    for flag, key in FLAGS.items():
        ann = _field(key).annotation
        choices = typing.get_args(ann) if typing.get_origin(ann) is typing.Literal else None
        kind = int if ann is int else (str if choices else float)
        text = _help(key)
        if flag == "method":
            text = "phase method: " + "; ".join(f"{n}: {e.summary}" for n, e in METHODS.items()) + " (default tv)"
        if ann is bool:  # --flag / --no-flag
            parser.add_argument(f"--{flag}", action=argparse.BooleanOptionalAction, default=None, help=text)
            continue
        metavar = None if choices else ("N" if kind is int else "VALUE")
        parser.add_argument(f"--{flag}", type=kind, choices=choices, metavar=metavar, help=text)
    parser.add_argument(
        "--roi",
        type=float,
        nargs=4,
        metavar=("XMIN", "XMAX", "YMIN", "YMAX"),
        help="region the 'multislice' model covers, µm from the optical axis (default: around the objects)",
    )
    parser.add_argument("--save", help=f"extra outputs, comma separated: {','.join(SAVE_CHOICES)}")
    parser.add_argument(
        "--store-digits",
        type=int,
        metavar="N",
        help=f"{OutputSettings.model_fields['store_digits'].description} (OUT.zarr only)",
    )


def optics_file(path) -> Optics:
    """The optics of an ``--optics`` YAML file; the paper's where none is given.

    Parameters
    ----------
    path : str or Path or None

    Returns
    -------
    Optics
    """
    return Optics.paper() if path is None else Optics.from_yaml(path)


def config_from_args(args: argparse.Namespace, optics: Optics | None, fallback: Optics | None = None) -> RunConfig:
    """The run configuration: the --config file (or defaults), then the flags given on top.

    Parameters
    ----------
    args : argparse.Namespace
        Parsed arguments with the options of :func:`add_reconstruction_options`.
    optics : Optics or None
        Optics given on the command line (--optics): they win over the config's.
    fallback : Optics, optional
        The optics where neither --optics nor the config name any (the calibration's).

    Returns
    -------
    RunConfig
    """
    if getattr(args, "config", None):
        cfg = RunConfig.from_yaml(args.config, default_optics=fallback)
    else:
        cfg = RunConfig(optics=fallback or Optics.paper())
    changes: dict = {}
    for flag, key in FLAGS.items():
        value = getattr(args, _dest(flag), None)
        if value is None:
            continue
        section, _, name = key.rpartition(".")
        if section:
            changes.setdefault(section, {})[name] = value
        else:
            changes[name] = value
    if getattr(args, "z", None) is not None:
        changes.update(z_min_um=float(args.z[0]), z_max_um=float(args.z[1]))
    if getattr(args, "roi", None) is not None:
        changes.setdefault("multislice", {})["roi_um"] = [float(v) for v in args.roi]
    rec = ReconstructionSettings.from_dict(merge_settings(cfg.reconstruction.to_dict(), changes), source="command line")
    return RunConfig(optics=optics or cfg.optics, reconstruction=rec, outputs=outputs_from_args(args, cfg.outputs))


def outputs_from_args(args: argparse.Namespace, outputs: OutputSettings | None = None) -> OutputSettings:
    """What a run writes: the --config file's ``outputs:`` section, with --save and --store-digits over it.

    Parameters
    ----------
    args : argparse.Namespace
        Parsed arguments with the options of :func:`add_reconstruction_options`.
    outputs : OutputSettings, optional
        The config's section when it is already read (else read from --config, or the defaults).

    Returns
    -------
    OutputSettings
    """
    if outputs is None:
        outputs = RunConfig.from_yaml(args.config).outputs if getattr(args, "config", None) else OutputSettings()
    changes = {k: getattr(args, k, None) for k in ("save", "store_digits")}
    if any(v is not None for v in changes.values()):
        data = {**outputs.to_dict(), **{k: v for k, v in changes.items() if v is not None}}
        outputs = OutputSettings.from_dict(data, source="command line")
    return outputs
