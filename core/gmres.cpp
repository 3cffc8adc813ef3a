// Restarted GMRES in a weighted inner product (core/gmres.h).
#include "core/gmres.h"

#include <cmath>

#include "core/half_buffer.h"
#include "core/malloc_policy.h"
#include "core/parallel.h"

namespace lpm {

namespace {

constexpr size_t kChunk = size_t(1) << 16;

/// <a, b>_w in fixed chunks, b(i) read through `second` (a float or a half buffer).
template <class Second>
double chunkedWeightedDot(const std::vector<double>& w, const std::vector<float>& a, const Second& second) {
    const size_t len = a.size();
    std::vector<double> part((len + kChunk - 1) / kChunk, 0.0);
    parallelForChunks(len, kChunk, [&](size_t b0, size_t e0) {
        double acc = 0;
        const size_t period = w.size();
        for (size_t i = b0, j = b0 % period; i < e0; ++i) {
            acc += w[j] * double(a[i]) * double(second(i));
            if (++j == period) j = 0;
        }
        part[b0 / kChunk] = acc;
    });
    double sum = 0;
    for (double v : part) sum += v;
    return sum;
}

double weightedDotHalf(const std::vector<double>& w, const std::vector<float>& a, const HalfBuffer& b) {
    const std::uint16_t* bits = b.bits.data();
    return double(b.scale) * chunkedWeightedDot(w, a, [bits](size_t i) { return floatFromHalf(bits[i]); });
}

/// y += a x for a Krylov vector x.
void axpy(std::vector<float>& y, double a, const HalfBuffer& x) {
    const double as = a * double(x.scale);
    parallelForChunks(y.size(), kChunk, [&](size_t b0, size_t e0) {
        for (size_t i = b0; i < e0; ++i) y[i] = float(double(y[i]) + as * double(floatFromHalf(x.bits[i])));
    });
}

/// v /= divisor, rounded to a Krylov vector; v becomes the rounded vector's exact value, so
/// the operator is applied to what the basis holds (the Arnoldi relation stays exact).
HalfBuffer normalisedKrylovVector(std::vector<float>& v, double divisor) {
    parallelForChunks(v.size(), kChunk, [&](size_t b0, size_t e0) {
        for (size_t i = b0; i < e0; ++i) v[i] = float(v[i] / divisor);
    });
    HalfBuffer h = HalfBuffer::encode(v);
    parallelForChunks(v.size(), kChunk, [&](size_t b0, size_t e0) {
        for (size_t i = b0; i < e0; ++i) v[i] = h.at(i);
    });
    return h;
}

/// Solves the k x k upper-triangular system H y = g and adds sum_i y_i V_i to X.
void updateSolution(const std::vector<std::vector<double>>& H, const std::vector<double>& g, int k,
                    const std::vector<HalfBuffer>& basis, std::vector<float>& X) {
    std::vector<double> y(k, 0.0);
    for (int i = k - 1; i >= 0; --i) {
        double acc = g[i];
        for (int j = i + 1; j < k; ++j) acc -= H[i][j] * y[j];
        y[i] = H[i][i] != 0 ? acc / H[i][i] : 0.0;
    }
    for (int i = 0; i < k; ++i) axpy(X, y[i], basis[i]);
}

/// Applies the Givens rotations of columns < k to column k of H, then the new rotation k,
/// to g as well; returns H[k + 1][k] as it was before rotation k zeroed it.
double rotateColumn(std::vector<std::vector<double>>& H, std::vector<double>& cs, std::vector<double>& sn,
                    std::vector<double>& g, int k) {
    for (int i = 0; i < k; ++i) {
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
    return hk1;
}

}  // namespace

double weightedDot(const std::vector<double>& w, const std::vector<float>& a, const std::vector<float>& b) {
    const float* bv = b.data();
    return chunkedWeightedDot(w, a, [bv](size_t i) { return bv[i]; });
}

GmresReport solveGmres(const LinearOperator& A, const std::vector<float>& B, const std::vector<double>& weights,
                       double target, int restart, const std::function<bool()>& mayApply, std::vector<float>& X) {
    const size_t len = B.size();
    GmresReport rep;
    rep.rhsNorm = std::sqrt(weightedDot(weights, B, B));
    // Full-length float vectors: X, v (the Krylov vector the operator is applied to) and w
    // (its product, orthogonalised into the next one), on huge pages: each is tens of MiB
    // on a coarse grid. B is the caller's. The basis is kept in half precision.
    assignZeroed(X, len);
    std::vector<float> v, w;
    assignZeroed(w, len);
    assignCopy(v, B);  // the first cycle's residual
    std::vector<HalfBuffer> basis;
    double rNorm = rep.rhsNorm;
    while (rNorm > target && mayApply()) {
        basis.clear();
        basis.push_back(normalisedKrylovVector(v, rNorm));
        std::vector<std::vector<double>> H(restart + 1, std::vector<double>(restart, 0.0));
        std::vector<double> cs(restart), sn(restart), g(restart + 1, 0.0);
        g[0] = rNorm;
        int k = 0;
        for (; k < restart && mayApply(); ++k) {
            A(v, w);
            ++rep.matvecs;
            for (int i = 0; i <= k; ++i) {  // modified Gram-Schmidt
                H[i][k] = weightedDotHalf(weights, w, basis[i]);
                axpy(w, -H[i][k], basis[i]);
            }
            H[k + 1][k] = std::sqrt(weightedDot(weights, w, w));
            const double hk1 = rotateColumn(H, cs, sn, g, k);
            // Converged, breakdown, or the cycle's end (V_{k+1} would not be used).
            if (std::fabs(g[k + 1]) <= target || hk1 <= 1e-30 * rep.rhsNorm || k + 1 == restart) {
                ++k;
                break;
            }
            std::swap(v, w);
            basis.push_back(normalisedKrylovVector(v, hk1));
        }
        updateSolution(H, g, k, basis, X);
        // True residual r = B - A X (one more product; keeps restarts honest, and corrects
        // what the half-precision basis rounded), formed in v for the next cycle.
        A(X, w);
        ++rep.matvecs;
        parallelForChunks(len, kChunk, [&](size_t b0, size_t e0) {
            for (size_t i = b0; i < e0; ++i) v[i] = B[i] - w[i];
        });
        rNorm = std::sqrt(weightedDot(weights, v, v));
    }
    rep.residualNorm = rNorm;
    rep.converged = rNorm <= target;
    return rep;
}

}  // namespace lpm
