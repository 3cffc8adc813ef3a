// Restarted GMRES in a weighted inner product (core/gmres.h).
#include "core/gmres.h"

#include <cmath>

#include "core/malloc_policy.h"
#include "core/parallel.h"

namespace lpm {

namespace {

constexpr size_t kChunk = size_t(1) << 16;

void axpy(std::vector<float>& y, double a, const std::vector<float>& x) {
    parallelForChunks(y.size(), kChunk, [&](size_t b0, size_t e0) {
        for (size_t i = b0; i < e0; ++i) y[i] = float(double(y[i]) + a * double(x[i]));
    });
}

void scale(std::vector<float>& v, double divisor) {
    for (float& x : v) x = float(x / divisor);
}

/// Solves the k x k upper-triangular system H y = g and adds sum_i y_i V_i to X.
void updateSolution(const std::vector<std::vector<double>>& H, const std::vector<double>& g, int k,
                    const std::vector<std::vector<float>>& basis, std::vector<float>& X) {
    std::vector<double> y(k, 0.0);
    for (int i = k - 1; i >= 0; --i) {
        double acc = g[i];
        for (int j = i + 1; j < k; ++j) acc -= H[i][j] * y[j];
        y[i] = H[i][i] != 0 ? acc / H[i][i] : 0.0;
    }
    for (int i = 0; i < k; ++i) axpy(X, y[i], basis[i]);
}

}  // namespace

double weightedDot(const std::vector<double>& w, const std::vector<float>& a, const std::vector<float>& b) {
    const size_t len = a.size();
    std::vector<double> part((len + kChunk - 1) / kChunk, 0.0);
    parallelForChunks(len, kChunk, [&](size_t b0, size_t e0) {
        double acc = 0;
        const size_t period = w.size();
        for (size_t i = b0, j = b0 % period; i < e0; ++i) {
            acc += w[j] * double(a[i]) * double(b[i]);
            if (++j == period) j = 0;
        }
        part[b0 / kChunk] = acc;
    });
    double sum = 0;
    for (double v : part) sum += v;
    return sum;
}

GmresReport solveGmres(const LinearOperator& A, const std::vector<float>& B, const std::vector<double>& weights,
                       double target, int restart, const std::function<bool()>& mayApply, std::vector<float>& X) {
    const size_t len = B.size();
    GmresReport rep;
    rep.rhsNorm = std::sqrt(weightedDot(weights, B, B));
    assignZeroed(X, len);  // X, w and the basis on huge pages: each is tens of MiB on a coarse grid
    // Full-length vectors alive in a cycle: X, w and the basis (B is the caller's). The
    // residual r starts each cycle as basis[0] (it is not needed again until the cycle's
    // end) and is formed in w's storage: no buffer of its own.
    std::vector<float> w;
    assignZeroed(w, len);
    std::vector<std::vector<float>> basis(1);
    assignCopy(basis[0], B);
    double rNorm = rep.rhsNorm;
    while (rNorm > target && mayApply()) {
        basis.resize(1);
        scale(basis[0], rNorm);
        std::vector<std::vector<double>> H(restart + 1, std::vector<double>(restart, 0.0));
        std::vector<double> cs(restart), sn(restart), g(restart + 1, 0.0);
        g[0] = rNorm;
        int k = 0;
        for (; k < restart && mayApply(); ++k) {
            A(basis[k], w);
            ++rep.matvecs;
            for (int i = 0; i <= k; ++i) {  // modified Gram-Schmidt
                H[i][k] = weightedDot(weights, w, basis[i]);
                axpy(w, -H[i][k], basis[i]);
            }
            H[k + 1][k] = std::sqrt(weightedDot(weights, w, w));
            for (int i = 0; i < k; ++i) {  // previous Givens rotations
                const double t = cs[i] * H[i][k] + sn[i] * H[i + 1][k];
                H[i + 1][k] = -sn[i] * H[i][k] + cs[i] * H[i + 1][k];
                H[i][k] = t;
            }
            const double den = std::hypot(H[k][k], H[k + 1][k]);
            cs[k] = den > 0 ? H[k][k] / den : 1.0;
            sn[k] = den > 0 ? H[k + 1][k] / den : 0.0;
            const double hk1 = H[k + 1][k];
            H[k][k] = cs[k] * H[k][k] + sn[k] * hk1;
            H[k + 1][k] = 0;
            g[k + 1] = -sn[k] * g[k];
            g[k] = cs[k] * g[k];
            if (std::fabs(g[k + 1]) <= target || hk1 <= 1e-30 * rep.rhsNorm) {
                ++k;
                break;
            }
            if (k + 1 == restart) {  // the cycle ends: V_{k+1} would not be used
                ++k;
                break;
            }
            basis.emplace_back();
            assignCopy(basis.back(), w);
            scale(basis.back(), hk1);
        }
        updateSolution(H, g, k, basis, X);
        // True residual r = B - A X (one more product; keeps restarts honest), formed in
        // w's storage and moved to basis[0] for the next cycle.
        A(X, w);
        ++rep.matvecs;
        parallelForChunks(len, kChunk, [&](size_t b0, size_t e0) {
            for (size_t i = b0; i < e0; ++i) w[i] = B[i] - w[i];
        });
        rNorm = std::sqrt(weightedDot(weights, w, w));
        std::swap(basis[0], w);
    }
    rep.residualNorm = rNorm;
    rep.converged = rNorm <= target;
    return rep;
}

}  // namespace lpm
