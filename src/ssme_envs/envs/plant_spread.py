"""Plants drawn per episode: a nozzle joint whose parameters each episode draws afresh.

A :class:`PlantSpread` is a Gaussian over the normalized joint parameters (J, b, k_el, k_hys,
beta_n, gamma_n, n), truncated at +-3 standard deviations of each underlying normal:

- ``relative``: each of J, b, k_el, k_hys, beta_n and gamma_n times ``exp(s z)``, z standard
  normal, independent (a log-normal spread, ``s`` about the relative standard deviation for small
  ``s``); the exponent n is kept (it shapes the loop rather than scaling it);
- ``uncertainty``: ``theta = theta_0 + R z`` with ``R R^T`` the covariance a model.json carries
  (its ``bouc_wen`` block, else its ``linear`` one), times ``scale``.

The normals come from the episode's own uniform draws (the last ``draw_size`` of them), by the
same Box-Muller routine as the sensor noise, and every parameter is computed by elementwise
operations in a fixed order: an env drawn alone gets the same bits as in a batch.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ssme_envs.envs.references import normal_rows
from ssme_envs.envs.task import check_number, real_number, shown
from ssme_envs.models.nozzle_joint import NozzleParameters, RK4Parameters, rk4_parameters
from ssme_envs.models.nozzle_model import NozzleModel
from ssme_envs.models.uncertainty import PSD_TOL

NAMES = ("J", "b", "k_el", "k_hys", "beta_n", "gamma_n", "n")
RELATIVE = ("J", "b", "k_el", "k_hys", "beta_n", "gamma_n")  # the exponent n is kept
TRUNCATION = 3.0  # standard deviations of each underlying normal
MAX_RELATIVE_SPREAD = 0.5
# the lowest value a drawn parameter may reach at the truncation, as a fraction of its nominal one
# (an additive spread must not reach a massless, unsprung or reversed joint)
POSITIVE_FLOOR = {"J": 0.05, "k_el": 0.0, "k_hys": 0.0, "b": 0.0, "beta_n": 0.0, "gamma_n": 0.0, "n": 0.05}


@dataclass(frozen=True, eq=False)
class PlantSpread:
    """How each episode's joint is drawn: ``theta = mean * exp(root @ z)`` (``relative``) or
    ``mean + root @ z``, with z standard normal truncated at +-:data:`TRUNCATION`.

    Parameters
    ----------
    mean : ndarray, shape (7,)
        The nominal normalized parameters, in :data:`NAMES` order.
    root : ndarray, shape (7, m)
        One column per normal drawn.
    relative : bool
        Multiplicative (log-normal) or additive draws.
    description : str
        What the spread is, for docs and reports.
    """

    mean: np.ndarray
    root: np.ndarray
    relative: bool
    description: str

    @classmethod
    def relative_spread(cls, joint: NozzleParameters, spread: float) -> PlantSpread:
        """Independent log-normal factors ``exp(spread z)`` on J, b, k_el, k_hys, beta_n, gamma_n."""
        if not 0.0 < spread <= MAX_RELATIVE_SPREAD:
            raise ValueError(f"plant_spread must be in (0, {MAX_RELATIVE_SPREAD:g}], got {shown(spread)}")
        root = np.zeros((len(NAMES), len(RELATIVE)))
        for j, name in enumerate(RELATIVE):
            root[NAMES.index(name), j] = spread
        norm = joint.normalized()
        return cls(
            np.array([norm[k] for k in NAMES]),
            root,
            True,
            f"relative spread {spread:g} (log-normal, +-3 sigma)",
        )

    @classmethod
    def from_model(cls, joint: NozzleParameters, model: NozzleModel, scale: float = 1.0) -> PlantSpread:
        """The covariance ``model`` carries about ``joint`` (its plant), standard deviations times
        ``scale``; ValueError if it carries none, or if the truncated draws could reach a
        parameter that is not positive."""
        if model.bouc_wen is not None and model.bouc_wen_uncertainty is not None:
            block, names = model.bouc_wen_uncertainty, model.bouc_wen_uncertainty.parameters
        elif model.bouc_wen is None and model.linear_uncertainty is not None:
            block = model.linear_uncertainty
            names = tuple("k_el" if name == "k" else name for name in block.parameters)
        else:
            raise ValueError(
                "plant_spread='uncertainty' needs a model.json with an uncertainty block for its plant "
                "(identify it with this version, or give a relative spread such as plant_spread=0.1)"
            )
        # a square root of the correlation (scale-free: the parameters' units differ by 10 orders
        # of magnitude, so round-off eigenvalues are judged on it), scaled back by the deviations
        sd = block.standard_errors
        unit = np.where(sd > 0, sd, 1.0)
        values, vectors = np.linalg.eigh(block.covariance / np.outer(unit, unit))
        factor = (
            sd[:, None]
            * vectors
            * np.sqrt(np.clip(values, PSD_TOL * max(values.max(initial=0.0), 0.0), None))
        )
        root = np.zeros((len(NAMES), len(names)))
        for i, name in enumerate(names):
            root[NAMES.index(name)] = scale * factor[i]
        norm = joint.normalized()
        spread = cls(
            np.array([norm[k] for k in NAMES]), root, False,
            f"the model's parameter covariance{'' if scale == 1 else f' x {scale:g}^2'} (+-3 sigma)",
        )  # fmt: skip
        low, _ = spread.bounds()
        for name, value, nominal in zip(NAMES, low, spread.mean, strict=True):
            # (a negative beta_n is a Bouc-Wen shape of its own: the corners' joints check it)
            if nominal > 0 and value < POSITIVE_FLOOR[name] * nominal:
                raise ValueError(
                    f"plant_spread='uncertainty' (scale {scale:g}) lets {name} reach {value:.4g} at 3 sigma "
                    f"(nominal {nominal:.4g}): too wide for a physical joint; lower uncertainty_scale"
                )
        return spread

    @property
    def normals(self) -> int:
        return self.root.shape[1]

    @property
    def draw_size(self) -> int:
        """Uniform numbers an episode's draw consumes (an even count: Box-Muller pairs)."""
        return self.normals + self.normals % 2

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """The lowest and highest value each parameter reaches within the truncation."""
        reach = TRUNCATION * np.abs(self.root).sum(axis=1)
        if self.relative:
            return self.mean * np.exp(-reach), self.mean * np.exp(reach)
        return self.mean - reach, self.mean + reach

    def corners(self) -> list[NozzleParameters]:
        """Joints at every corner of the bounds of the parameters that vary (to size RK4's
        substeps for the worst of them), the nominal joint first."""
        low, high = self.bounds()
        varying = [i for i in range(len(NAMES)) if high[i] > low[i]]
        joints = [_joint(self.mean)]
        for corner in itertools.product((0, 1), repeat=len(varying)):
            values = self.mean.copy()
            for i, side in zip(varying, corner, strict=True):
                values[i] = (low, high)[side][i]
            joints.append(_joint(values))
        return joints

    def draw(self, uniforms: np.ndarray) -> dict[str, np.ndarray]:
        """The normalized parameters of k episodes, (k,) float64 each, from their uniforms
        (draw_size, k) float32."""
        z = normal_rows(uniforms, self.draw_size // 2, 0, self.normals).astype(np.float64)
        np.clip(z, -TRUNCATION, TRUNCATION, out=z)
        out = {}
        for i, name in enumerate(NAMES):
            # a fixed order of elementwise operations (no matmul, whose kernel depends on k)
            acc = np.zeros(z.shape[1])
            for j in np.flatnonzero(self.root[i]).tolist():
                acc = acc + self.root[i, j] * z[j]
            out[name] = self.mean[i] * np.exp(acc) if self.relative else self.mean[i] + acc
        return out

    def rk4(self, uniforms: np.ndarray, hysteretic: bool, n: int | None) -> RK4Parameters:
        """The integrator parameters of the drawn joints: floats (``n`` None, one episode) or
        (n,) arrays."""
        params = rk4_parameters(self.draw(uniforms))._replace(hysteretic=hysteretic)
        if n is None:
            return RK4Parameters(*(v if isinstance(v, bool) else float(v[0]) for v in params))
        return params


def covered_joints(joint: NozzleParameters, spread: PlantSpread | None) -> list[NozzleParameters]:
    """The joints an env's RK4 substeps must serve: ``joint`` alone, or every corner of the
    spread around it (the nominal first)."""
    return [joint] if spread is None else spread.corners()


def _joint(values: np.ndarray) -> NozzleParameters:
    norm = dict(zip(NAMES, values.tolist(), strict=True))
    return NozzleParameters.from_normalized(**norm, A=1.0)


def resolve_spread(
    plant_spread: float | str | None, joint: NozzleParameters, plant: Any, uncertainty_scale: float
) -> PlantSpread | None:
    """The spread an env option asks for: None (or 0), a relative spread, or ``"uncertainty"``
    (the model.json's covariance; ``plant`` a model path, a model, or an identified preset)."""
    # checked whether used or not: a typo in it is never silently ignored
    scale = check_number("uncertainty_scale", uncertainty_scale, 0.0, 100.0, low_open=True)
    if plant_spread is None:
        return None
    if isinstance(plant_spread, str):
        if plant_spread != "uncertainty":
            raise ValueError(f"plant_spread must be a number or 'uncertainty', got {shown(plant_spread)}")
        return PlantSpread.from_model(joint, _model_of(plant), scale)
    spread = real_number(plant_spread)  # numpy numbers as floats; an int too large for one is inf
    if spread is None or not math.isfinite(spread):
        raise ValueError(f"plant_spread must be a number or 'uncertainty', got {shown(plant_spread)}")
    return None if spread == 0 else PlantSpread.relative_spread(joint, spread)


def _model_of(plant: Any) -> NozzleModel:
    from ssme_envs.models.nozzle import identified_nozzle

    if isinstance(plant, NozzleModel):
        return plant
    if plant in ("identified", "strong_identified"):
        return identified_nozzle("table1" if plant == "identified" else "strong")
    if isinstance(plant, str | Path) and str(plant).endswith(".json"):
        return NozzleModel.load(plant)
    raise ValueError(
        f"plant_spread='uncertainty' needs plant='identified', 'strong_identified', a model.json or a "
        f"model (whose covariance it draws from), got plant={shown(plant)}"
    )


__all__ = ["NAMES", "TRUNCATION", "PlantSpread", "covered_joints", "resolve_spread"]
