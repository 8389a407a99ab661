"""The nozzle model file (model.json): an identified joint with its fit and uncertainty."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ssme_envs.models.linear import describe, finite_float, refuse_unknown_keys
from ssme_envs.models.nozzle_joint import NozzleParameters
from ssme_envs.models.statespace import as_matrix, dumps_compact, read_json
from ssme_envs.models.uncertainty import ParameterUncertainty, check_standard_errors

NOZZLE_MODEL_SCHEMA = "ssme-envs/nozzle-model"
# Version 2 added the optional ``uncertainty`` blocks in ``linear`` and ``bouc_wen``; version 1
# files (without them) still load.
NOZZLE_MODEL_SCHEMA_VERSION = 2
_READABLE_VERSIONS = (1, 2)
_LINEAR_MATRICES = ("A", "B", "C", "D", "K")
_LINEAR_KEYS = (*_LINEAR_MATRICES, "dt", "J", "b", "k")  # besides an optional "uncertainty"
_TOP_KEYS = frozenset(("schema", "schema_version", "input_name", "output_name", "linear", "bouc_wen", "fit"))
LINEAR_UNCERTAIN = ("J", "b", "k")
BOUC_WEN_UNCERTAIN = ("J", "b", "k_el", "k_hys", "beta_n", "gamma_n", "n")


def _read_uncertainty(block: Any, known: tuple[str, ...], where: str) -> ParameterUncertainty:
    """An ``uncertainty`` block of model.json (see :class:`NozzleModel`); ValueError naming the flaw."""
    try:
        result = ParameterUncertainty.from_dict(block, known, f"{where}.uncertainty")
    except OverflowError:  # its checks convert with float(), which an integer past 1e308 overflows
        raise ValueError(f"{where}.uncertainty holds an integer too large for a float") from None
    listed = block.get("standard_errors")
    if listed is not None:
        check_standard_errors(listed, result, f"{where}.uncertainty.standard_errors")
    return result


@dataclass
class NozzleModel:
    """A nozzle model.json: the linear innovations model with its J, b, k, and the Bouc-Wen joint.

    Attributes
    ----------
    linear : dict
        ``A, B, C, D, K`` (arrays) of ``x(k+1) = A x + B tau + K e``, ``beta = C x + D tau + e``
        at ``dt`` (s), and ``J``, ``b``, ``k`` from its continuous transfer function.
    bouc_wen : NozzleParameters or None
        The hysteretic joint, or None when the data did not determine it.
    fit : dict
        Fit figures and provenance (JSON-serializable).
    linear_uncertainty : ParameterUncertainty or None
        Covariance of ``J``, ``b``, ``k`` (parameters named "J", "b", "k").
    bouc_wen_uncertainty : ParameterUncertainty or None
        Covariance of the Bouc-Wen joint's normalized parameters "J", "b", "k_el", "k_hys",
        "beta_n", "gamma_n", "n" (:meth:`NozzleParameters.normalized`), the ones the data
        determine; only with ``bouc_wen``.

    In model.json each covariance is an ``uncertainty`` object inside ``linear`` and inside
    ``bouc_wen``: ``{"parameters": [names], "covariance": [[...]], "standard_errors": [...],
    "method": "...", "samples": N}``, the covariance in the parameters' units squared (J in
    kg m^2, b in N m s/rad, k, k_el, k_hys in N m/rad, the rest dimensionless), the standard
    errors the square roots of its diagonal. The block is optional (schema version 2).
    """

    linear: dict[str, Any]
    bouc_wen: NozzleParameters | None
    fit: dict[str, Any]
    input_name: str = "tau"
    output_name: str = "beta"
    linear_uncertainty: ParameterUncertainty | None = None
    bouc_wen_uncertainty: ParameterUncertainty | None = None

    def __post_init__(self) -> None:
        for name, uncertainty, known in (
            ("linear", self.linear_uncertainty, LINEAR_UNCERTAIN),
            ("bouc_wen", self.bouc_wen_uncertainty, BOUC_WEN_UNCERTAIN),
        ):
            if uncertainty is None:
                continue
            if not isinstance(uncertainty, ParameterUncertainty):
                raise ValueError(f"{name} uncertainty must be a ParameterUncertainty")
            unknown = sorted(set(uncertainty.parameters) - set(known))
            if unknown:
                raise ValueError(f"{name}.uncertainty names parameters the model lacks: {', '.join(unknown)}")
        if self.bouc_wen_uncertainty is not None and self.bouc_wen is None:
            raise ValueError("bouc_wen.uncertainty is given but the Bouc-Wen joint is not")
        lin = dict(self.linear)
        if "uncertainty" in lin:
            raise ValueError(
                "linear: give the covariance as linear_uncertainty, not a linear['uncertainty'] entry"
            )
        missing = [key for key in _LINEAR_KEYS if key not in lin]
        if missing:
            raise ValueError(f"linear: missing key(s) {', '.join(missing)}")
        a = as_matrix(lin["A"], "linear.A", (None, None))
        n = a.shape[0]
        if a.shape[1] != n:
            raise ValueError(f"linear.A must be square, got shape {a.shape}")
        lin["A"] = a
        lin["B"] = as_matrix(lin["B"], "linear.B", (n, 1))
        lin["C"] = as_matrix(lin["C"], "linear.C", (1, n))
        lin["D"] = as_matrix(lin["D"], "linear.D", (1, 1))
        lin["K"] = as_matrix(lin["K"], "linear.K", (n, 1))
        for key in ("dt", "J", "b", "k"):
            value = finite_float(lin[key], f"linear.{key}")
            if value < 0 or (key != "b" and value == 0):
                kind = ">= 0 (damping)" if key == "b" else "positive"
                raise ValueError(f"linear.{key} must be {kind}, got {describe(lin[key])}")
            lin[key] = value
        self.linear = lin

    @property
    def dt(self) -> float:
        return self.linear["dt"]

    def plant(self) -> NozzleParameters:
        """The joint to simulate: the Bouc-Wen one when determined, else the linear J, b, k."""
        if self.bouc_wen is not None:
            return self.bouc_wen
        return NozzleParameters.linear(self.linear["J"], self.linear["b"], self.linear["k"])

    def to_dict(self) -> dict[str, Any]:
        lin = {
            key: (value.tolist() if isinstance(value, np.ndarray) else value)
            for key, value in self.linear.items()
        }
        if self.linear_uncertainty is not None:
            lin["uncertainty"] = self.linear_uncertainty.to_dict()
        bw = None if self.bouc_wen is None else self.bouc_wen.to_dict()
        if bw is not None and self.bouc_wen_uncertainty is not None:
            bw["uncertainty"] = self.bouc_wen_uncertainty.to_dict()
        return {
            "schema": NOZZLE_MODEL_SCHEMA,
            "schema_version": NOZZLE_MODEL_SCHEMA_VERSION,
            "input_name": self.input_name,
            "output_name": self.output_name,
            "linear": lin,
            "bouc_wen": bw,
            "fit": self.fit,
        }

    @classmethod
    def from_dict(cls, data: Any, source: str = "model") -> NozzleModel:
        if not isinstance(data, dict):
            raise ValueError(f"{source}: expected a JSON object, got {type(data).__name__}")
        if data.get("schema") != NOZZLE_MODEL_SCHEMA:
            schema = describe(data.get("schema"))
            raise ValueError(f"{source}: schema is {schema}, expected {NOZZLE_MODEL_SCHEMA!r}")
        version = data.get("schema_version")
        if isinstance(version, bool) or version not in _READABLE_VERSIONS:
            raise ValueError(
                f"{source}: unsupported schema_version {describe(version)} "
                f"(expected one of {list(_READABLE_VERSIONS)})"
            )
        if not isinstance(data.get("linear"), dict):
            raise ValueError(f"{source}: 'linear' must be an object with A, B, C, D, K, dt, J, b, k")
        refuse_unknown_keys(data, _TOP_KEYS, f"{source}: ")
        linear = dict(data["linear"])
        refuse_unknown_keys(linear, (*_LINEAR_KEYS, "uncertainty"), f"{source}: linear: ")
        bw = data.get("bouc_wen")
        uncertainty: dict[str, ParameterUncertainty | None] = {"linear": None, "bouc_wen": None}
        try:
            if "uncertainty" in linear:
                uncertainty["linear"] = _read_uncertainty(
                    linear.pop("uncertainty"), LINEAR_UNCERTAIN, "linear"
                )
            if bw is not None:
                if not isinstance(bw, dict):
                    raise ValueError("'bouc_wen' must be an object or null")
                bw = dict(bw)
                if "uncertainty" in bw:
                    uncertainty["bouc_wen"] = _read_uncertainty(
                        bw.pop("uncertainty"), BOUC_WEN_UNCERTAIN, "bouc_wen"
                    )
                refuse_unknown_keys(bw, NozzleParameters.__dataclass_fields__, "bouc_wen: ")
                missing = sorted(set(NozzleParameters.__dataclass_fields__) - set(bw))
                if missing:
                    raise ValueError(f"bouc_wen: missing key(s) {', '.join(missing)}")
                bw = NozzleParameters(**bw)
            fit = data.get("fit", {})
            if not isinstance(fit, dict):
                raise ValueError("fit must be an object")
            for key in ("input_name", "output_name"):
                if not isinstance(data.get(key, "x"), str):
                    raise ValueError(f"{key} must be a string")
            return cls(
                linear=linear,
                bouc_wen=bw,
                fit=dict(fit),
                input_name=str(data.get("input_name", "tau")),
                output_name=str(data.get("output_name", "beta")),
                linear_uncertainty=uncertainty["linear"],
                bouc_wen_uncertainty=uncertainty["bouc_wen"],
            )
        except ValueError as exc:
            raise ValueError(f"{source}: {exc}") from None
        except (TypeError, OverflowError) as exc:  # a value of a type no check foresaw
            raise ValueError(f"{source}: not a nozzle model ({type(exc).__name__}: {exc})") from None

    def save(self, path: str | Path) -> None:
        from ssme_envs.outputs import write_text  # atomic: a reader never sees half a model

        write_text(path, dumps_compact(self.to_dict()) + "\n")

    @classmethod
    def load(cls, path: str | Path) -> NozzleModel:
        return cls.from_dict(read_json(path), source=str(path))


__all__ = [
    "BOUC_WEN_UNCERTAIN",
    "LINEAR_UNCERTAIN",
    "NOZZLE_MODEL_SCHEMA",
    "NOZZLE_MODEL_SCHEMA_VERSION",
    "NozzleModel",
]
