"""Type stubs of the extension module ``actrack._actrack`` (checked against the runtime by
``crates/py/tests/test_stubs.py``)."""

import os
from collections.abc import Iterable, Sequence
from typing import Any, Literal, final

import numpy as np
import numpy.typing as npt

__version__: str

_F64 = npt.NDArray[np.float64]
_I64 = npt.NDArray[np.int64]
_ArrayLike = npt.ArrayLike
_Path = str | os.PathLike[str]
_EndMode = Literal["must_end", "free", "none"]
_CovType = Literal["full", "diag"]

class ActrackError(ValueError):
    """Invalid input or model: bad shapes, non-finite values, inconsistent parameters, malformed files."""

class ActrackOSError(OSError):
    """A file could not be read or written (errno, strerror and filename are set)."""

@final
class FitReport:
    """What a fit did: iterations, the log-likelihood history and whether it converged."""

    @property
    def iterations(self) -> int: ...
    @property
    def log_likelihoods(self) -> _F64: ...
    @property
    def converged(self) -> bool: ...

@final
class ThetaEstimate:
    """The result of θ estimation: θ̂ (caller units), log P(X | θ̂), EM iterations and history."""

    @property
    def theta(self) -> _F64: ...
    @property
    def log_likelihood(self) -> float: ...
    @property
    def iterations(self) -> int: ...
    @property
    def history(self) -> _F64: ...

@final
class Hmm:
    """A plain left-right Gaussian HMM (numpy in, numpy out)."""

    @classmethod
    def from_params(
        cls,
        startprob: _ArrayLike,
        transmat: _ArrayLike,
        means: _ArrayLike,
        covars: _ArrayLike,
        *,
        exitprob: _ArrayLike | None = None,
        max_jump: int | None = None,
        end_mode: _EndMode | None = None,
    ) -> Hmm: ...
    @classmethod
    def fit(
        cls,
        sequences: _ArrayLike,
        *,
        n_states: int | None = None,
        max_jump: int = 3,
        covariance_type: _CovType = "full",
        end_mode: _EndMode = "must_end",
        n_iter: int = 100,
        tol: float = 0.0001,
        cov_floor: float = 0.005,
        min_occupancy: float | None = None,
        transition_floor: float = 0.0,
        learn_startprob: bool = False,
        init: Hmm | None = None,
    ) -> Hmm: ...
    @classmethod
    def load(cls, path: _Path) -> Hmm: ...
    @classmethod
    def from_json(cls, text: str) -> Hmm: ...
    def save(self, path: _Path) -> None: ...
    def to_json(self) -> str: ...
    @property
    def n_states(self) -> int: ...
    @property
    def dim(self) -> int: ...
    @property
    def max_jump(self) -> int: ...
    @property
    def end_mode(self) -> _EndMode: ...
    @property
    def covariance_type(self) -> _CovType: ...
    @property
    def startprob(self) -> _F64: ...
    @property
    def transmat(self) -> _F64: ...
    @property
    def exitprob(self) -> _F64: ...
    @property
    def means(self) -> _F64: ...
    @property
    def covars(self) -> _F64: ...
    @property
    def fit_report(self) -> FitReport | None: ...
    def log_likelihood(self, x: _ArrayLike) -> float: ...
    def posteriors(self, x: _ArrayLike) -> _F64: ...
    def viterbi(self, x: _ArrayLike) -> tuple[_I64, float]: ...
    def sample(self, *, length: int | None = None, seed: int = 0) -> tuple[_F64, _I64]: ...
    def expected_trajectory(self, *, length: int | None = None) -> _F64: ...

@final
class Phmm:
    """A linear parametric HMM: μ_i(θ) = mean_bias_i + mean_weights_i · θ."""

    @classmethod
    def from_params(
        cls,
        startprob: _ArrayLike,
        transmat: _ArrayLike,
        mean_bias: _ArrayLike,
        mean_weights: _ArrayLike,
        covars: _ArrayLike,
        *,
        exitprob: _ArrayLike | None = None,
        max_jump: int | None = None,
        end_mode: _EndMode | None = None,
    ) -> Phmm: ...
    @classmethod
    def fit(
        cls,
        sequences: _ArrayLike,
        thetas: _ArrayLike,
        *,
        n_states: int | None = None,
        max_jump: int = 3,
        covariance_type: _CovType = "full",
        end_mode: _EndMode = "must_end",
        n_iter: int = 100,
        tol: float = 0.0001,
        cov_floor: float = 0.005,
        min_occupancy: float | None = None,
        transition_floor: float = 0.0,
        learn_startprob: bool = False,
        init: Phmm | None = None,
    ) -> Phmm: ...
    @classmethod
    def load(cls, path: _Path) -> Phmm: ...
    @classmethod
    def from_json(cls, text: str) -> Phmm: ...
    def save(self, path: _Path) -> None: ...
    def to_json(self) -> str: ...
    @property
    def n_states(self) -> int: ...
    @property
    def dim(self) -> int: ...
    @property
    def theta_dim(self) -> int: ...
    @property
    def max_jump(self) -> int: ...
    @property
    def end_mode(self) -> _EndMode: ...
    @property
    def covariance_type(self) -> _CovType: ...
    @property
    def startprob(self) -> _F64: ...
    @property
    def transmat(self) -> _F64: ...
    @property
    def exitprob(self) -> _F64: ...
    @property
    def mean_bias(self) -> _F64: ...
    @property
    def mean_weights(self) -> _F64: ...
    @property
    def covars(self) -> _F64: ...
    @property
    def fit_report(self) -> FitReport | None: ...
    def means(self, theta: _ArrayLike) -> _F64: ...
    def log_likelihood(self, x: _ArrayLike, theta: _ArrayLike) -> float: ...
    def posteriors(self, x: _ArrayLike, theta: _ArrayLike) -> _F64: ...
    def viterbi(self, x: _ArrayLike, theta: _ArrayLike) -> tuple[_I64, float]: ...
    def estimate_theta(
        self,
        x: _ArrayLike,
        *,
        init: _ArrayLike | None = None,
        n_iter: int = 50,
        tol: float = 1e-06,
        prior: tuple[_ArrayLike, _ArrayLike] | None = None,
        multi_start: bool = False,
    ) -> ThetaEstimate: ...
    def sample(
        self, theta: _ArrayLike, *, length: int | None = None, seed: int = 0
    ) -> tuple[_F64, _I64]: ...
    def expected_trajectory(self, theta: _ArrayLike, *, length: int | None = None) -> _F64: ...

@final
class ActionModel:
    """Several named actions, one parametric HMM each (the model files of ``actrack-cli train``)."""

    @classmethod
    def train(
        cls,
        manifest: _Path,
        *,
        states: int | None = None,
        max_jump: int | None = None,
        n_iter: int | None = None,
        cov_floor: float | None = None,
    ) -> ActionModel: ...
    @classmethod
    def load_default(cls) -> ActionModel: ...
    @classmethod
    def load(cls, path: _Path) -> ActionModel: ...
    @classmethod
    def from_json(cls, text: str) -> ActionModel: ...
    def save(self, path: _Path) -> None: ...
    def to_json(self) -> str: ...
    @property
    def actions(self) -> list[str]: ...
    def phmm(self, action: str) -> Phmm: ...
    @property
    def arm_lengths(self) -> tuple[float, float]: ...
    @property
    def provenance(self) -> dict[str, Any]: ...
    def classify(
        self, x: _ArrayLike, *, partial: bool = False, multi_start: bool = False
    ) -> dict[str, Any]: ...

@final
class Scene:
    """A scene: cameras, the table region, the actor's placement, the arm geometry."""

    @classmethod
    def load(cls, path: _Path) -> Scene: ...
    @classmethod
    def parse(cls, text: str) -> Scene: ...
    @classmethod
    def default(cls, width: int = 640, height: int = 480) -> Scene: ...
    def to_toml(self) -> str: ...
    @property
    def cameras(self) -> list[str]: ...
    @property
    def image_sizes(self) -> list[tuple[int, int]]: ...
    @property
    def theta_region(self) -> tuple[_F64, _F64]: ...
    @property
    def table_height(self) -> float: ...
    def project(self, points: _ArrayLike, *, camera: int = 0) -> _F64: ...
    def pose_to_world(self, poses: _ArrayLike) -> _F64: ...
    def pose_to_actor(self, poses: _ArrayLike) -> _F64: ...
    def theta_to_world(self, theta: _ArrayLike) -> _F64: ...

def load_mocap(
    path: _Path,
    *,
    static_trial: _Path | None = None,
    arm: Literal["R", "L", "r", "l", "right", "left"] = "R",
    theta: _ArrayLike | None = None,
    frame_rate: float | None = 30.0,
    trim: bool = True,
    max_gap: int = 10,
) -> dict[str, _F64]: ...
def evaluate(track: _Path, truth: _Path) -> dict[str, Any]: ...

@final
class Estimate:
    """One frame's estimate of the tracker."""

    @property
    def frame(self) -> int: ...
    @property
    def action_posterior(self) -> dict[str, float]: ...
    @property
    def action(self) -> str: ...
    @property
    def theta_mean(self) -> _F64: ...
    @property
    def theta_std(self) -> _F64: ...
    @property
    def theta_world(self) -> _F64: ...
    @property
    def entropy(self) -> float: ...
    @property
    def ess(self) -> float: ...
    @property
    def progress(self) -> float: ...
    @property
    def degenerate(self) -> bool: ...
    @property
    def best_pose(self) -> _F64: ...
    @property
    def smoothed_pose(self) -> _F64: ...

_Config = _Path | dict[str, Any]
_Preset = Literal["default", "paper"]

@final
class Tracker:
    """The tracker of an action model in a scene (``actrack::Session``), one frame at a time.

    The configuration (a ``TrackConfig``, docs/configuration.md) is ``config`` (a TOML file, or
    a dict of keys over ``preset``) or ``preset`` (``"default"`` when not given), then ``set``
    (``["key=value", ...]``), then ``n_particles`` (``filter.particles``) and ``seed``
    (``filter.seed``). An invalid configuration raises :class:`ActrackError` naming the key.
    ``Estimate.smoothed_pose`` is the causal median; the centred median (``output.median =
    "centred"``, the default preset's) needs the whole video: :func:`track_video`.
    """

    def __new__(
        cls,
        model: ActionModel,
        scene: Scene,
        *,
        config: _Config | None = None,
        preset: _Preset | None = None,
        n_particles: int | None = None,
        seed: int | None = None,
        set: str | Sequence[str] | None = None,
    ) -> Tracker: ...
    @property
    def actions(self) -> list[str]: ...
    @property
    def config(self) -> str: ...
    @property
    def config_dict(self) -> dict[str, Any]: ...
    @property
    def frames(self) -> int: ...
    def step(self, frame: npt.NDArray[np.uint8] | Sequence[npt.NDArray[np.uint8]]) -> Estimate: ...
    def track(self, frames: Iterable[npt.NDArray[np.uint8]]) -> dict[str, npt.NDArray[Any]]: ...

def track_video(
    model: ActionModel,
    scene: Scene,
    source: _Path,
    *,
    mcap: _Path | None = None,
    csv: _Path | None = None,
    mcap_images: bool = False,
    config: _Config | None = None,
    preset: _Preset | None = None,
    n_particles: int | None = None,
    seed: int | None = None,
    set: str | Sequence[str] | None = None,
    fps: float | None = None,
) -> dict[str, Any]: ...
def centred_median(poses: _ArrayLike, window: int = 7) -> _F64: ...
def edge_image(
    frame: npt.NDArray[np.uint8],
    *,
    sigma: float | None = None,
    tau: float | None = None,
    binary: bool | None = None,
    colour: bool = False,
) -> npt.NDArray[np.float32]: ...
def contour_likelihood(
    scene: Scene,
    edges: _ArrayLike | Sequence[_ArrayLike],
    poses: _ArrayLike,
    *,
    model: ActionModel | None = None,
    arm_lengths: tuple[float, float] | None = None,
) -> _F64: ...
