"""JSON of the engine models (schema ``ssme-envs/engine-model``) and the package's JSON helpers.

:func:`dumps_compact` writes one matrix row per line (readable diffs, exact float round trip);
:func:`read_json` names the file in every error. :class:`AlphaCanonicalModel`'s ``to_dict``,
``from_dict``, ``save`` and ``load`` call the functions here.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from ssme_envs.input_files import read_or_refuse
from ssme_envs.models.linear import describe, refuse_unknown_keys
from ssme_envs.models.uncertainty import ParameterUncertainty, check_standard_errors

if TYPE_CHECKING:
    from ssme_envs.models.statespace import AlphaCanonicalModel

ENGINE_MODEL_SCHEMA = "ssme-envs/engine-model"
# Version 2 added C = H [0 I] and the optional ``uncertainty`` block; version 1 files still load.
ENGINE_MODEL_SCHEMA_VERSION = 2
SUPPORTED_ENGINE_SCHEMA_VERSIONS = (1, 2)
# Identified engine models have tens of states (indices up to 6 per output by default); the bound
# keeps a corrupt or hostile file from costing minutes and gigabytes in the checks below.
MAX_MODEL_STATES = 512
_ENGINE_KEYS = frozenset((
    "schema", "schema_version", "dt", "A", "B", "C", "observability_indices", "lambda", "input_names",
    "output_names", "fit", "uncertainty",
))  # fmt: skip
# Model files are kB to a few MB; the bound keeps a wrong path (a disk image, a log) from being read.
MAX_JSON_BYTES = 64 * 1024 * 1024


def engine_model_to_dict(model: AlphaCanonicalModel) -> dict[str, Any]:
    """The JSON dictionary of an engine model (schema ssme-envs/engine-model, current version)."""
    return {
        "schema": ENGINE_MODEL_SCHEMA,
        "schema_version": ENGINE_MODEL_SCHEMA_VERSION,
        "dt": model.dt,
        "A": model.A.tolist(),
        "B": model.B.tolist(),
        "C": model.C.tolist(),
        "observability_indices": list(model.observability_indices),
        "lambda": model.lam.tolist(),
        "input_names": list(model.input_names),
        "output_names": list(model.output_names),
        "fit": model.fit,
        **({"uncertainty": model.uncertainty.to_dict()} if model.uncertainty is not None else {}),
    }


def engine_model_from_dict(
    cls: type[AlphaCanonicalModel], data: Any, source: str = "model"
) -> AlphaCanonicalModel:
    """Build a ``cls`` model from its JSON dictionary, checking everything a user file can get wrong
    (ValueErrors naming ``source``)."""
    if not isinstance(data, dict):
        raise ValueError(f"{source}: expected a JSON object, got {type(data).__name__}")
    schema = data.get("schema", ENGINE_MODEL_SCHEMA)
    if schema != ENGINE_MODEL_SCHEMA:
        raise ValueError(f"{source}: schema is {describe(schema)}, expected {ENGINE_MODEL_SCHEMA!r}")
    version = data.get("schema_version", ENGINE_MODEL_SCHEMA_VERSION)
    if isinstance(version, bool) or version not in SUPPORTED_ENGINE_SCHEMA_VERSIONS:
        raise ValueError(
            f"{source}: unsupported schema_version {describe(version)} "
            f"(expected one of {list(SUPPORTED_ENGINE_SCHEMA_VERSIONS)})"
        )
    hint = f" (an engine model holds {', '.join(sorted(_ENGINE_KEYS))}; it has no feedthrough D)"
    refuse_unknown_keys(data, _ENGINE_KEYS, f"{source}: ", hint)
    missing = [k for k in ("dt", "A", "B", "C", "observability_indices", "lambda") if k not in data]
    if missing:
        raise ValueError(f"{source}: missing key(s) {', '.join(missing)}")
    try:
        m = len(data["B"][0])
        p = len(data["C"])
    except (TypeError, IndexError, KeyError):
        raise ValueError(f"{source}: B and C must be non-empty lists of rows") from None
    indices = data["observability_indices"]
    integers = isinstance(indices, list) and all(type(v) is int for v in indices)  # JSON true is no index
    if not integers:
        raise ValueError(f"{source}: observability_indices must be a list of integers")
    # before any array is built: the checks below cost n^2 p, the model's use more. The indices
    # must sum to n, checked before their structure is built.
    if isinstance(data["A"], list) and len(data["A"]) > MAX_MODEL_STATES:
        raise ValueError(
            f"{source}: A has {len(data['A'])} rows (states); a model file holds at most {MAX_MODEL_STATES}"
        )
    names = {}
    for key, count, prefix in (("input_names", m, "u"), ("output_names", p, "y")):
        value = data.get(key, [f"{prefix}{i}" for i in range(count)])
        if not isinstance(value, list) or not all(isinstance(v, str) for v in value):
            raise ValueError(f"{source}: {key} must be a list of strings")
        names[key] = tuple(value)
    fit = data.get("fit", {})
    if not isinstance(fit, dict):
        raise ValueError(f"{source}: fit must be an object")
    try:
        model = cls(
            A=data["A"],
            B=data["B"],
            C=data["C"],
            dt=data["dt"],
            observability_indices=tuple(indices),
            lam=data["lambda"],
            fit=dict(fit),
            **names,
        )
    except ValueError as exc:
        raise ValueError(f"{source}: not an engine model: {exc}") from None
    except (TypeError, OverflowError) as exc:  # a value of a type no check above foresaw
        raise ValueError(f"{source}: not an engine model ({type(exc).__name__}: {exc})") from None
    outside = model.gains_outside_range()
    if outside.size:  # u* = u + (lambda - 1)|u|: lambda u above the operating point, (2 - lambda) u below
        raise ValueError(
            f"{source}: lambda must lie in (0, 2), got {describe(model.lam.tolist())}: outside it the "
            f"valve gain on one side of the operating point changes sign (input {int(outside[0])})"
        )
    residual = model.alpha_canonical_residual()
    if not residual <= 1e-9 * max(1.0, float(np.max(np.abs(model.A)))):  # NaN (an overflowing K) fails
        raise ValueError(
            f"{source}: (A, C) is not in alpha-canonical form for observability indices "
            f"{list(model.observability_indices)} (largest violation of eqs 5-8: {residual:.3g})"
        )
    if data.get("uncertainty") is not None:
        try:
            model.uncertainty = ParameterUncertainty.from_dict(
                data["uncertainty"], model.parameter_names(), source
            )
        except OverflowError:  # its checks convert with float(), which an integer past 1e308 overflows
            raise ValueError(f"{source}: uncertainty holds an integer too large for a float") from None
        listed = data["uncertainty"].get("standard_errors")  # an object: from_dict checked it
        if listed is not None:  # read as the nozzle's are: numbers, the covariance's square roots
            try:
                check_standard_errors(listed, model.uncertainty, "uncertainty.standard_errors")
            except ValueError as exc:
                raise ValueError(f"{source}: {exc}") from None
    return model


def save_engine_model(model: AlphaCanonicalModel, path: str | Path) -> None:
    """Write ``model`` as JSON at ``path``, atomically: a reader never sees half a model."""
    from ssme_envs.outputs import write_text

    write_text(path, dumps_compact(engine_model_to_dict(model)) + "\n")


class _DuplicateKey(ValueError):
    """A key that appears twice in one JSON object."""


def _unique_keys(pairs: list[tuple[str, Any]]) -> dict[str, Any]:
    """A JSON object's pairs as a dict, refusing a repeated key (json keeps the last silently)."""
    out: dict[str, Any] = {}
    for key, value in pairs:
        if key in out:
            raise _DuplicateKey(key)
        out[key] = value
    return out


def read_json(path: str | Path) -> Any:
    """Parse a JSON file; a missing, special or oversized file, bad JSON or a key repeated in an
    object (which JSON readers resolve differently) is a ValueError naming it."""
    path = Path(path)
    raw = read_or_refuse(path, MAX_JSON_BYTES, "valid JSON", "a model file")
    try:
        return json.loads(raw.decode("utf-8"), object_pairs_hook=_unique_keys)
    except _DuplicateKey as exc:
        raise ValueError(f"{path}: key {str(exc)!r} appears twice in one object (which counts?)") from None
    except RecursionError:
        raise ValueError(f"{path}: nested too deeply to read as JSON") from None
    except json.JSONDecodeError as exc:
        raise ValueError(f"{path}: not valid JSON ({exc})") from None
    except UnicodeDecodeError as exc:
        raise ValueError(f"{path}: not valid JSON, not UTF-8 text ({exc})") from None
    except ValueError as exc:  # Python's bound on the digits of an integer, the one other ValueError
        raise ValueError(f"{path}: a number in it is too long to read ({str(exc).split(';')[0]})") from None


def dumps_compact(obj: Any) -> str:
    """JSON with one matrix row per line: readable diffs, exact round trip of floats.

    NaN and inf are refused (ValueError naming where they are): they are not JSON.
    """

    def scalar(value: Any, where: str) -> str:
        try:
            return json.dumps(value, allow_nan=False)
        except ValueError:  # the one ValueError of these dumps: a NaN or an infinity
            raise ValueError(
                f"{where or 'the value'} holds NaN or inf, which a JSON file cannot store "
                "(the computation gave a non-finite result on this input: it may not suit this model)"
            ) from None

    def render(value: Any, indent: int, where: str) -> str:
        pad = " " * indent
        if isinstance(value, dict):
            if not value:
                return "{}"
            items = [
                f"{pad} {json.dumps(k)}: {render(v, indent + 1, f'{where}.{k}' if where else str(k))}"
                for k, v in value.items()
            ]
            return "{\n" + ",\n".join(items) + "\n" + pad + "}"
        if isinstance(value, list) and value and all(isinstance(v, list) for v in value):
            rows = [f"{pad} {scalar(v, where)}" for v in value]
            return "[\n" + ",\n".join(rows) + "\n" + pad + "]"
        if isinstance(value, list) and any(isinstance(v, dict) for v in value):
            rows = [f"{pad} {render(v, indent + 1, f'{where}[{i}]')}" for i, v in enumerate(value)]
            return "[\n" + ",\n".join(rows) + "\n" + pad + "]"
        return scalar(value, where)

    return render(obj, 0, "")


__all__ = [
    "ENGINE_MODEL_SCHEMA",
    "ENGINE_MODEL_SCHEMA_VERSION",
    "MAX_JSON_BYTES",
    "MAX_MODEL_STATES",
    "SUPPORTED_ENGINE_SCHEMA_VERSIONS",
    "dumps_compact",
    "engine_model_from_dict",
    "engine_model_to_dict",
    "read_json",
    "save_engine_model",
]
