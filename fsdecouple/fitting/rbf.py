"""RBF neural-network baselines of Section 4: the standard MIMO network and six SISO chi.

Both are built as MATLAB's ``newrb`` builds them (Section 4.1: spread 1, MSE goal
2.4e-6): Gaussian units ``radbas(n) = exp(-n^2)`` with ``n = ||x - c|| b`` and
``b = sqrt(-ln 0.5) / spread = 0.8326 / spread``, and a linear output layer with
bias.  Centres are added one at a time from the training inputs by newrb's
orthogonal least squares until the training MSE (mean over all outputs, in the
targets' units squared) is below the goal.  The paper chose the goal "small enough
to ensure that all training data be selected as centers"; that is what happens to
the MIMO network on noisy calibration data (forces in N cannot be fitted to 2.4e-6
N^2), and then the all-centres network is computed directly instead of by 300 OLS
steps.  The SISO networks' targets are coupling errors in volts, which a handful of
centres fit to 2.4e-6 V^2, so their OLS loop stops early: "defined the same as the
MIMO RBF NN" (Section 4.2) taken literally.  Exactly identical input vectors (the
zero-load point of every sweep) are one candidate centre.

The output layer ``[W b]`` solves ``Phi W + 1 b = T`` as newrb does with MATLAB's
``/``: a QR factorisation with column pivoting (LAPACK geqp3, via scipy) and the
*basic* solution, which keeps the first ``r`` pivoted columns, with ``r`` the
number of ``|R_ii| > max(m, n) eps |R_11|``, and sets the other weights to zero.
The Gaussian matrix with spread 1 on volt-sized inputs is numerically rank
deficient, so this choice matters: a minimum-norm (SVD) solution would give a
different, smoother network.  The solve is deterministic: the same data give
bit-identical weights.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..axes import DEFAULT, NamedChi
from ..core.decouple import decouple_exact

SPREAD = 1.0  # Section 4.1: "the variance is set to 1"
MSE_GOAL = 2.4e-6  # Section 4.1
B_FACTOR = float(np.sqrt(-np.log(0.5)))  # 0.8326: radbas(b * spread) = 0.5
OUTPUT_LAYER = (
    "centres by newrb's orthogonal least squares until the training MSE < goal (all distinct "
    "training inputs when even all of them miss it); [W b] is the basic least-squares "
    "solution of [Phi 1][W; b] = T by QR with column pivoting (scipy.linalg.qr, LAPACK "
    "geqp3), rank r = #{|R_ii| > max(m, n) eps |R_11|}, the other weights zero (newrb's '/')"
)
_CHUNK_ELEMENTS = 1 << 20


@dataclass(frozen=True)
class RBFNetwork:
    """A radial basis network ``y = sum_j w_j exp(-(b ||x/s - c_j||)^2) + bias``.

    Attributes
    ----------
    centres : ndarray, shape (m, d)
        Centres c_j, in the scaled input units.
    weights : ndarray, shape (m, k)
        Output weights; zero for centres outside the basic solution.
    bias : ndarray, shape (k,)
        Output bias.
    b : float
        0.8326 / spread.
    input_scale : ndarray, shape (d,)
        Inputs are divided by this before the distance (1 for volts as they are).
    rank : int
        Numerical rank of ``[Phi 1]`` used by the basic solution.
    train_mse : float
        MATLAB's ``mse`` on the training data: mean squared error over all outputs.
    """

    centres: np.ndarray
    weights: np.ndarray
    bias: np.ndarray
    b: float
    input_scale: np.ndarray
    rank: int
    train_mse: float = float("nan")

    def design(self, x: np.ndarray) -> np.ndarray:
        """Hidden-layer outputs, shape (n, m)."""
        x = np.asarray(x, dtype=float).reshape(-1, self.centres.shape[1]) / self.input_scale
        d2 = ((x[:, None, :] - self.centres[None, :, :]) ** 2).sum(axis=2)
        return np.exp(-(self.b * self.b) * d2)

    def __call__(self, x: np.ndarray) -> np.ndarray:
        """Network outputs, shape (n, k)."""
        x = np.asarray(x, dtype=float).reshape(-1, self.centres.shape[1])
        out = np.empty((x.shape[0], self.weights.shape[1]))
        step = max(1, _CHUNK_ELEMENTS // max(1, self.centres.size))
        for start in range(0, x.shape[0], step):
            out[start:start + step] = self.design(x[start:start + step]) @ self.weights + self.bias
        return out


def basic_solution(m: np.ndarray, t: np.ndarray) -> tuple[np.ndarray, int]:
    """The basic least-squares solution of ``m x = t`` (MATLAB's ``\\`` for a non-square m).

    QR with column pivoting, ``m P = Q R``; rank r = #{|R_ii| > max(rows, cols) eps |R_11|};
    ``x[P[:r]] = R[:r, :r]^-1 Q[:, :r]^T t`` and the other rows of x are zero.
    """
    from scipy.linalg import qr, solve_triangular  # 0.4 s to import: cv imports it beside the SVRs

    q, r, perm = qr(m, mode="economic", pivoting=True)
    diag = np.abs(np.diag(r))
    tol = max(m.shape) * np.finfo(float).eps * (diag[0] if diag.size else 0.0)
    rank = int((diag > tol).sum())
    x = np.zeros((m.shape[1], t.shape[1]))
    if rank:
        x[perm[:rank]] = solve_triangular(r[:rank, :rank], q[:, :rank].T @ t)
    return x, rank


def _output_layer(phi: np.ndarray, t: np.ndarray) -> tuple[np.ndarray, int, float]:
    """newrb's ``solvelin2``: ``[W; b]`` of ``[Phi 1][W; b] = T`` (basic solution), rank, MSE."""
    m = np.hstack([phi, np.ones((phi.shape[0], 1))])
    sol, rank = basic_solution(m, t)
    return sol, rank, float(np.mean((m @ sol - t) ** 2))


def _ols_order(phi: np.ndarray, t: np.ndarray, goal: float):
    """newrb's orthogonal-least-squares loop: yield (used centres, W, rank, MSE) per neuron.

    As MATLAB's ``designrb``: the candidate column with the largest
    ``sum_o ((P_j . d_o)^2 / (|d_o|^2 |P_j|^2))^2`` is added (0/0 counts as 0; first
    of equal maxima), the remaining candidates are orthogonalised against it, the
    output layer is solved with the centres used so far, and the loop stops from the
    second neuron on once the training MSE is below ``goal``.
    """
    p = phi.copy()
    dd = (t * t).sum(axis=0)
    left = list(range(phi.shape[1]))
    used: list[int] = []
    w = None
    for k in range(phi.shape[1]):
        if w is not None:
            p -= np.outer(w, (w @ p) / (w @ w))
        pp = (p * p).sum(axis=0)
        with np.errstate(divide="ignore", invalid="ignore"):
            e = (p.T @ t) ** 2 / np.outer(pp, dd)
        e[~np.isfinite(e)] = 0.0
        pick = int(np.argmax((e * e).sum(axis=1)))
        w = p[:, pick].copy()
        p = np.delete(p, pick, axis=1)
        used.append(left.pop(pick))
        sol, rank, mse = _output_layer(phi[:, used], t)
        yield list(used), sol, rank, mse
        if k >= 1 and mse < goal:
            return


def fit_rbf(
    x: np.ndarray, t: np.ndarray, *, spread: float = SPREAD, input_scale=None,
    goal: float = MSE_GOAL,
) -> RBFNetwork:
    """Design an RBF network on inputs ``x`` (n, d) and targets ``t`` (n, k) as newrb does.

    newrb adds centres by orthogonal least squares until the training MSE is below
    ``goal``.  Every distinct input is a candidate centre.  If even all of them
    together miss the goal, newrb uses them all (a least-squares residual never
    grows when columns are added, so no earlier network met the goal either) and the
    all-centres network is returned directly; otherwise the OLS loop runs and stops
    at the first network that meets the goal.
    """
    x = np.asarray(x, dtype=float)
    x = x.reshape(x.shape[0], -1)
    t = np.asarray(t, dtype=float).reshape(x.shape[0], -1)
    scale = np.ones(x.shape[1]) if input_scale is None else np.asarray(input_scale, dtype=float)
    xs = x / scale
    # first occurrence order, so the design does not depend on sorting
    _, first = np.unique(xs, axis=0, return_index=True)
    centres = xs[np.sort(first)]
    b = B_FACTOR / spread
    probe = RBFNetwork(centres, np.zeros((len(centres), t.shape[1])), np.zeros(t.shape[1]), b,
                       scale, 0)
    phi = probe.design(x)
    sol, rank, mse = _output_layer(phi, t)
    used = list(range(len(centres)))
    if mse < goal:
        for used, sol, rank, mse in _ols_order(phi, t, goal):  # noqa: B007
            pass
    return RBFNetwork(centres[used], sol[:-1], sol[-1], b, scale, rank, mse)


@dataclass(frozen=True)
class MimoRBF:
    """The standard MIMO RBF network of Section 4.1: voltages (N) in, forces (N) out."""

    net: RBFNetwork

    def decouple(self, u: np.ndarray, *, rotate: bool = False) -> np.ndarray:
        del rotate
        return self.net(np.asarray(u, dtype=float).reshape(-1, self.net.centres.shape[1]))


def fit_mimo(
    u: np.ndarray, f: np.ndarray, *, spread: float = SPREAD, input_scale=None,
    goal: float = MSE_GOAL,
) -> MimoRBF:
    """Fit the black-box network on all training points, ``u`` [V] -> ``f`` [N]."""
    return MimoRBF(fit_rbf(u, f, spread=spread, input_scale=input_scale, goal=goal))


@dataclass(frozen=True)
class SisoChi(NamedChi):
    """A corrected coupling function chi_ab (eq. 4) approximated by a 1-D RBF network."""

    name: str
    net: RBFNetwork
    pair: tuple[int, int] | None = None  # (output a, input b); None: an "xy" name

    def __call__(self, u: np.ndarray) -> np.ndarray:
        u = np.asarray(u, dtype=float)
        return self.net(u.reshape(-1, 1))[:, 0].reshape(u.shape)


@dataclass(frozen=True)
class SisoRBFModel:
    """The coupling error model with six SISO RBF networks in place of the SVRs (Figure 7)."""

    k: np.ndarray
    chi: dict[str, SisoChi]

    def decouple(self, u: np.ndarray, *, rotate: bool = False) -> np.ndarray:
        """Eq. (11) with the RBF chi: f_a = (u_a - chi_ab(u_b) - chi_ac(u_c)) / k_aa."""
        del rotate
        return decouple_exact(np.asarray(u, dtype=float).reshape(-1, len(self.k)), self.k,
                              self.chi.values())


def fit_siso(
    k: np.ndarray, data: dict[str, tuple[np.ndarray, np.ndarray]], *, spread: float = SPREAD,
    input_scale=None, goal: float = MSE_GOAL, layout=DEFAULT,
) -> SisoRBFModel:
    """Six 1-D networks, ``data[name] = (u_b, u_a)`` of the b sweeps (as for the SVRs).

    ``input_scale[b]`` divides the input of every chi_ab (1 for volts as they are).
    """
    chi = {}
    for name, (x, y) in data.items():
        a, b = layout.pair(name)
        s = None if input_scale is None else [float(input_scale[b])]
        chi[name] = SisoChi(name, fit_rbf(x, y, spread=spread, input_scale=s, goal=goal),
                            None if layout.is_default else (a, b))
    return SisoRBFModel(np.asarray(k, dtype=float), chi)
