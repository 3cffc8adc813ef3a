// Restarted GMRES (Saad and Schultz 1986, "GMRES: a generalized minimal residual algorithm
// for solving nonsymmetric linear systems", SIAM J. Sci. Stat. Comput. 7(3)), with
// modified Gram-Schmidt and Givens rotations, in a weighted inner product
// <a, b> = sum_i w_(i mod P) a_i b_i: the P weights repeat (one voxel's bins and channels),
// so they cost no memory of the vectors' size. The solver uses it on the scattering-order iteration:
// (I - K) X = B with K one propagation pass (docs/lpm_solver.md). Every reduction is
// chunked in a fixed order, so results do not depend on the thread count.
#pragma once

#include <functional>
#include <vector>

namespace lpm {

struct GmresReport {
    int matvecs = 0;          ///< applications of A, the true-residual ones included
    double rhsNorm = 0;       ///< ||B||_w
    double residualNorm = 0;  ///< ||B - A X||_w at the end
    bool converged = false;   ///< residualNorm <= target
};

struct HalfBuffer;

/// y = A x (y has x's size on entry).
using LinearOperator = std::function<void(const std::vector<float>& x, std::vector<float>& y)>;
/// y = A x for x held in half precision (a Krylov vector; y has x's size on entry).
using HalfOperator = std::function<void(const HalfBuffer& x, std::vector<float>& y)>;

/// Solves A X = B from X = 0 until ||B - A X||_w <= target, in cycles of at most `restart`
/// Krylov vectors, each closed by one true-residual product. `mayApply` is asked before
/// each product of a cycle and before each new cycle; false stops (a pass budget).
GmresReport solveGmres(const LinearOperator& A, const std::vector<float>& B, const std::vector<double>& weights,
                       double target, int restart, const std::function<bool()>& mayApply, std::vector<float>& X);

/// The same for B held in half precision, with the Krylov vectors handed to `onBasis` as
/// they are stored (A still forms the true residual's product A X): GMRES then holds two
/// float vectors (X and one product) instead of four (docs/lpm_solver.md, "Krylov
/// acceleration"). onBasis(x) must equal A applied to x's exact value. With
/// `firstResidual` (B - A X_0, formed by the caller; its storage is taken over), X holds
/// X_0 on entry and GMRES starts from it; rhsNorm is then that residual's norm.
GmresReport solveGmres(const LinearOperator& A, const HalfOperator& onBasis, const HalfBuffer& B,
                       const std::vector<double>& weights, double target, int restart,
                       const std::function<bool()>& mayApply, std::vector<float>& X,
                       std::vector<float> firstResidual = {});

/// <a, b>_w summed in fixed chunks (thread-count independent); w repeats with period w.size().
double weightedDot(const std::vector<double>& w, const std::vector<float>& a, const std::vector<float>& b);

}  // namespace lpm
