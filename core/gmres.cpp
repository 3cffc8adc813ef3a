// Restarted GMRES in a weighted inner product (core/gmres.h).
#include "core/gmres.h"

#include <cmath>
#include <utility>

#include "core/half_buffer.h"
#include "core/malloc_policy.h"
#include "core/parallel.h"
#include "core/simd_clones.h"

namespace lpm {

namespace {

constexpr size_t kChunk = size_t(1) << 16;
constexpr size_t kLanes = 8;  // a chunk's dot product: 8 partial sums, lane i % 8 (vectorizes)

/// The weights w_(i mod P) written out to a length that is a multiple of both P and
/// kLanes, so a run of kLanes elements starting at a multiple of kLanes reads contiguous
/// weights.
std::vector<double> lanedWeights(const std::vector<double>& w) {
    size_t length = w.size();
    while (length % kLanes) length += w.size();
    std::vector<double> out(length);
    for (size_t i = 0; i < length; ++i) out[i] = w[i % w.size()];
    return out;
}

/// acc[i % kLanes] += wx[i mod |wx|] a_i second(i) for i in [b0, e0), b0 a multiple of kLanes.
template <class Second>
inline void addLaneProducts(const std::vector<double>& wx, const float* a, Second second, size_t b0, size_t e0,
                            double* acc) {
    size_t j = b0 % wx.size(), i = b0;
    for (; i + kLanes <= e0; i += kLanes) {
        for (size_t l = 0; l < kLanes; ++l) acc[l] += wx[j + l] * double(a[i + l]) * double(second(i + l));
        j += kLanes;
        if (j == wx.size()) j = 0;
    }
    for (size_t l = 0; i < e0; ++i, ++l) acc[l] += wx[j + l] * double(a[i]) * double(second(i));
}

LPM_SIMD_CLONES
void laneProductsFloat(const std::vector<double>& wx, const float* a, const float* b, size_t b0, size_t e0,
                       double* acc) {
    addLaneProducts(
        wx, a, [b](size_t i) { return b[i]; }, b0, e0, acc);
}

LPM_SIMD_CLONES
void laneProductsHalf(const std::vector<double>& wx, const float* a, const std::uint16_t* b, size_t b0, size_t e0,
                      double* acc) {
    addLaneProducts(
        wx, a, [b](size_t i) { return floatFromHalf(b[i]); }, b0, e0, acc);
}

/// <a, b>_w (b read by `chunkProducts`): lane sums per chunk, chunks summed in order, so
/// the result depends neither on the thread count nor on how the weights' period is written.
template <class ChunkProducts>
double chunkedDot(size_t len, const ChunkProducts& chunkProducts) {
    std::vector<double> part((len + kChunk - 1) / kChunk, 0.0);
    parallelForChunks(len, kChunk, [&](size_t b0, size_t e0) {
        double acc[kLanes] = {};
        chunkProducts(b0, e0, acc);
        double sum = 0;
        for (double lane : acc) sum += lane;
        part[b0 / kChunk] = sum;
    });
    double sum = 0;
    for (double v : part) sum += v;
    return sum;
}

double dotFloat(const std::vector<double>& wx, const std::vector<float>& a, const std::vector<float>& b) {
    return chunkedDot(
        a.size(), [&](size_t b0, size_t e0, double* acc) { laneProductsFloat(wx, a.data(), b.data(), b0, e0, acc); });
}

double dotHalf(const std::vector<double>& wx, const std::vector<float>& a, const HalfBuffer& b) {
    return double(b.scale) * chunkedDot(a.size(), [&](size_t b0, size_t e0, double* acc) {
               laneProductsHalf(wx, a.data(), b.bits.data(), b0, e0, acc);
           });
}

LPM_SIMD_CLONES
void axpyRange(float* y, double a, const std::uint16_t* x, size_t b0, size_t e0) {
    for (size_t i = b0; i < e0; ++i) y[i] = float(double(y[i]) + a * double(floatFromHalf(x[i])));
}

/// y += a x for a Krylov vector x.
void axpy(std::vector<float>& y, double a, const HalfBuffer& x) {
    const double as = a * double(x.scale);
    parallelForChunks(y.size(), kChunk, [&](size_t b0, size_t e0) { axpyRange(y.data(), as, x.bits.data(), b0, e0); });
}

LPM_SIMD_CLONES
void roundRange(float* v, double divisor, float scale, std::uint16_t* bits, size_t b0, size_t e0) {
    const float inverse = 1.0f / scale;  // a power of two: exact
    for (size_t i = b0; i < e0; ++i) {
        bits[i] = halfFromFloat(float(v[i] / divisor) * inverse);
        v[i] = floatFromHalf(bits[i]) * scale;
    }
}

/// v / divisor rounded to a Krylov vector; v becomes the rounded vector's exact value, so
/// the operator is applied to what the basis holds (the Arnoldi relation stays exact).
HalfBuffer normalisedKrylovVector(std::vector<float>& v, double divisor) {
    HalfBuffer h;
    h.scale = HalfBuffer::scaleFor(float(largestFinite(v) / divisor));
    assignZeroed(h.bits, v.size());
    parallelForChunks(v.size(), kChunk,
                      [&](size_t b0, size_t e0) { roundRange(v.data(), divisor, h.scale, h.bits.data(), b0, e0); });
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
    return dotFloat(lanedWeights(w), a, b);
}

namespace {

/// B read element by element: a float vector's or a half buffer's.
struct FloatRhs {
    const std::vector<float>& b;
    float at(size_t i) const { return b[i]; }
    size_t size() const { return b.size(); }
};

/// r = B - Ax (B alone when Ax is null).
template <class Rhs>
void formResidual(const Rhs& B, const std::vector<float>* Ax, std::vector<float>& r) {
    parallelForChunks(B.size(), kChunk, [&](size_t b0, size_t e0) {
        for (size_t i = b0; i < e0; ++i) r[i] = Ax ? B.at(i) - (*Ax)[i] : B.at(i);
    });
}

/// The restarted cycles. With onBasis, A is applied to each Krylov vector as stored and the
/// product w is rounded in place into the next one; without, to v, the float copy of it.
template <class Rhs>
GmresReport runCycles(const LinearOperator& A, const HalfOperator* onBasis, const Rhs& B,
                      const std::vector<double>& weights, double target, int restart,
                      const std::function<bool()>& mayApply, std::vector<float>& X, std::vector<float> firstResidual) {
    const size_t len = B.size();
    GmresReport rep;
    const std::vector<double> wx = lanedWeights(weights);
    // Full-length float vectors: X, w (a product, orthogonalised into the next Krylov
    // vector) and, without onBasis, v (the vector the operator is applied to), on huge
    // pages: each is tens of MiB on a coarse grid. The basis is kept in half precision.
    const bool fromGuess = firstResidual.size() == len;
    if (!fromGuess) assignZeroed(X, len);
    std::vector<float> v, w;
    if (!onBasis) assignZeroed(v, len);
    std::vector<float>& r = onBasis ? w : v;  // the residual, each cycle's first vector
    if (fromGuess) r.swap(firstResidual);     // the caller's storage
    if (w.size() != len) assignZeroed(w, len);
    if (!fromGuess) formResidual(B, nullptr, r);
    firstResidual = std::vector<float>();
    rep.rhsNorm = std::sqrt(dotFloat(wx, r, r));
    std::vector<HalfBuffer> basis;
    double rNorm = rep.rhsNorm;
    while (rNorm > target && mayApply()) {
        basis.clear();
        basis.push_back(normalisedKrylovVector(r, rNorm));
        std::vector<std::vector<double>> H(restart + 1, std::vector<double>(restart, 0.0));
        std::vector<double> cs(restart), sn(restart), g(restart + 1, 0.0);
        g[0] = rNorm;
        int k = 0;
        for (; k < restart && mayApply(); ++k) {
            if (onBasis) (*onBasis)(basis[size_t(k)], w);
            else A(v, w);
            ++rep.matvecs;
            for (int i = 0; i <= k; ++i) {  // modified Gram-Schmidt
                H[i][k] = dotHalf(wx, w, basis[i]);
                axpy(w, -H[i][k], basis[i]);
            }
            H[k + 1][k] = std::sqrt(dotFloat(wx, w, w));
            const double hk1 = rotateColumn(H, cs, sn, g, k);
            // Converged, breakdown, or the cycle's end (V_{k+1} would not be used).
            if (std::fabs(g[k + 1]) <= target || hk1 <= 1e-30 * rep.rhsNorm || k + 1 == restart) {
                ++k;
                break;
            }
            if (!onBasis) std::swap(v, w);
            basis.push_back(normalisedKrylovVector(onBasis ? w : v, hk1));
        }
        updateSolution(H, g, k, basis, X);
        // True residual r = B - A X (one more product; keeps restarts honest, and corrects
        // what the half-precision basis rounded), formed for the next cycle.
        A(X, w);
        ++rep.matvecs;
        formResidual(B, &w, r);
        rNorm = std::sqrt(dotFloat(wx, r, r));
    }
    rep.residualNorm = rNorm;
    rep.converged = rNorm <= target;
    return rep;
}

}  // namespace

GmresReport solveGmres(const LinearOperator& A, const std::vector<float>& B, const std::vector<double>& weights,
                       double target, int restart, const std::function<bool()>& mayApply, std::vector<float>& X) {
    return runCycles(A, nullptr, FloatRhs{B}, weights, target, restart, mayApply, X, {});
}

GmresReport solveGmres(const LinearOperator& A, const HalfOperator& onBasis, const HalfBuffer& B,
                       const std::vector<double>& weights, double target, int restart,
                       const std::function<bool()>& mayApply, std::vector<float>& X, std::vector<float> firstResidual) {
    return runCycles(A, &onBasis, B, weights, target, restart, mayApply, X, std::move(firstResidual));
}

}  // namespace lpm
