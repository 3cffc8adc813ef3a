// Restarted GMRES (core/gmres.h) against a direct solve of small nonsymmetric systems.
#include "core/gmres.h"

#include <gtest/gtest.h>

#include <cmath>

#include "core/half_buffer.h"
#include "core/parallel.h"
#include "core/rng.h"

using namespace lpm;

namespace {

/// A = I - K with K a random nonnegative matrix of row sums `rho` (a scattering pass).
std::vector<std::vector<double>> makeSystem(int n, double rho, std::uint64_t seed) {
    Pcg32 rng(seed, 3);
    std::vector<std::vector<double>> K(n, std::vector<double>(n));
    for (auto& row : K) {
        double sum = 0;
        for (double& x : row) sum += (x = rng.uniform());
        for (double& x : row) x *= rho / sum;
    }
    return K;
}

LinearOperator operatorOf(const std::vector<std::vector<double>>& K) {
    return [&K](const std::vector<float>& x, std::vector<float>& y) {
        for (size_t i = 0; i < K.size(); ++i) {
            double acc = x[i];
            for (size_t j = 0; j < K.size(); ++j) acc -= K[i][j] * x[j];
            y[i] = float(acc);
        }
    };
}

/// Gaussian elimination with partial pivoting on (I - K) x = b.
std::vector<double> directSolve(const std::vector<std::vector<double>>& K, const std::vector<float>& b) {
    const size_t n = K.size();
    std::vector<std::vector<double>> a(n, std::vector<double>(n + 1));
    for (size_t i = 0; i < n; ++i) {
        for (size_t j = 0; j < n; ++j) a[i][j] = (i == j ? 1.0 : 0.0) - K[i][j];
        a[i][n] = b[i];
    }
    for (size_t c = 0; c < n; ++c) {
        size_t p = c;
        for (size_t r = c + 1; r < n; ++r)
            if (std::fabs(a[r][c]) > std::fabs(a[p][c])) p = r;
        std::swap(a[c], a[p]);
        for (size_t r = c + 1; r < n; ++r) {
            const double f = a[r][c] / a[c][c];
            for (size_t j = c; j <= n; ++j) a[r][j] -= f * a[c][j];
        }
    }
    std::vector<double> x(n);
    for (size_t i = n; i-- > 0;) {
        double acc = a[i][n];
        for (size_t j = i + 1; j < n; ++j) acc -= a[i][j] * x[j];
        x[i] = acc / a[i][i];
    }
    return x;
}

/// Weights first, first + 1, ..., first + period - 1, repeated over n values.
std::vector<double> repeatingWeights(int n, double first, int period) {
    std::vector<double> w(n);
    for (int i = 0; i < n; ++i) w[i] = first + i % period;
    return w;
}

std::vector<float> randomRhs(int n, std::uint64_t seed) {
    Pcg32 rng(seed, 5);
    std::vector<float> b(n);
    for (float& x : b) x = float(rng.uniform());
    return b;
}

/// I - K of makeSystem(80, 0.95, seed), a right-hand side in half precision (b its decoded
/// value), and the operator on Krylov vectors as stored, counting its products.
struct HalfRhsSystem {
    static constexpr int n = 80;
    std::vector<std::vector<double>> K;
    HalfBuffer halfB;
    std::vector<float> b;
    std::vector<double> w;
    double bNorm;
    LinearOperator A;
    int basisProducts = 0;
    HalfOperator onBasis;
    explicit HalfRhsSystem(std::uint64_t seed)
        : K(makeSystem(n, 0.95, seed)), halfB(HalfBuffer::encode(randomRhs(n, seed + 1))), b(n),
          w(repeatingWeights(n, 1.0, 4)), bNorm(0), A(operatorOf(K)) {
        for (int i = 0; i < n; ++i) b[i] = halfB.at(size_t(i));
        bNorm = std::sqrt(weightedDot(w, b, b));
        onBasis = [this](const HalfBuffer& v, std::vector<float>& y) {
            std::vector<float> x(v.size());
            for (size_t i = 0; i < v.size(); ++i) x[i] = v.at(i);
            ++basisProducts;
            A(x, y);
        };
    }
    HalfRhsSystem(const HalfRhsSystem&) = delete;
    HalfRhsSystem& operator=(const HalfRhsSystem&) = delete;
};

}  // namespace

TEST(Gmres, MatchesDirectSolveWithAndWithoutRestarts) {
    const int n = 60;
    const auto K = makeSystem(n, 0.98, 1);  // slow for plain iteration: 0.98 per pass
    const std::vector<float> b = randomRhs(n, 2);
    const std::vector<double> exact = directSolve(K, b);
    const std::vector<double> w(n, 1.0);
    for (int restart : {40, 5}) {
        std::vector<float> x;
        const GmresReport rep = solveGmres(
            operatorOf(K), b, w, 1e-6 * std::sqrt(double(n)), restart, [] { return true; }, x);
        EXPECT_TRUE(rep.converged) << "restart " << restart;
        double err = 0, norm = 0;
        for (int i = 0; i < n; ++i) {
            err = std::max(err, std::fabs(x[i] - exact[i]));
            norm = std::max(norm, std::fabs(exact[i]));
        }
        EXPECT_LT(err, 1e-4 * norm) << "restart " << restart;
        // Plain iteration needs log(1e-6)/log(0.98) ~ 680 passes; a rank-one-dominated K far fewer.
        EXPECT_LT(rep.matvecs, 100) << "restart " << restart;
    }
}

// The Krylov basis is held in half precision (2^-11 relative), yet restarts from the
// float residual B - A X refine the solution to far below that: the reported residual is
// the true one, recomputed here from X.
TEST(Gmres, ConvergesFarBelowTheBasisPrecision) {
    const int n = 80;
    const auto K = makeSystem(n, 0.95, 11);
    const std::vector<float> b = randomRhs(n, 12);
    const std::vector<double> w = repeatingWeights(n, 1.0, 4);
    const double bNorm = std::sqrt(weightedDot(w, b, b));
    for (int restart : {40, 4}) {
        std::vector<float> x, ax(n), r(n);
        const GmresReport rep = solveGmres(
            operatorOf(K), b, w, 1e-6 * bNorm, restart, [] { return true; }, x);
        operatorOf(K)(x, ax);
        for (int i = 0; i < n; ++i) r[i] = b[i] - ax[i];
        const double trueResidual = std::sqrt(weightedDot(w, r, r));
        EXPECT_TRUE(rep.converged) << "restart " << restart;
        EXPECT_LE(trueResidual, 1e-6 * bNorm) << "restart " << restart;
        EXPECT_NEAR(rep.residualNorm, trueResidual, 1e-3 * trueResidual) << "restart " << restart;
    }
}

// B in half precision with the operator applied to the Krylov vectors as stored: the same
// products on the same values as the float overload given B's decoded value, so the same X
// bit for bit, at restarts 40 and 4; and it solves the system of the rounded B.
TEST(Gmres, HalfRhsAndStoredBasisGiveTheFloatSolveOfTheRoundedRhs) {
    HalfRhsSystem sys(21);
    auto& [K, halfB, b, w, bNorm, A, basisProducts, onBasis] = sys;
    for (int restart : {40, 4}) {
        std::vector<float> xFloat, xHalf;
        const GmresReport rf = solveGmres(
            A, b, w, 1e-6 * bNorm, restart, [] { return true; }, xFloat);
        basisProducts = 0;
        const GmresReport rh = solveGmres(
            A, onBasis, halfB, w, 1e-6 * bNorm, restart, [] { return true; }, xHalf);
        EXPECT_TRUE(rh.converged) << "restart " << restart;
        EXPECT_EQ(rh.matvecs, rf.matvecs) << "restart " << restart;
        EXPECT_GT(basisProducts, 0);
        EXPECT_LT(basisProducts, rh.matvecs);  // the true residuals' products go to A
        EXPECT_EQ(rh.rhsNorm, rf.rhsNorm);
        EXPECT_EQ(rh.residualNorm, rf.residualNorm);
        EXPECT_TRUE(xHalf == xFloat) << "restart " << restart;
    }
}

// From a guess X_0 with the caller's first residual B - A X_0 (the coarse grid's start from
// its source sum): the solution of the same system, its true residual under the target,
// and from a guess near it in fewer products than from zero (a wrong first residual, B's,
// is caught by the restarts' true residuals, but costs products).
TEST(Gmres, StartsFromAGuessWithTheCallersFirstResidual) {
    HalfRhsSystem sys(23);
    const int n = HalfRhsSystem::n;
    auto& [K, halfB, b, w, bNorm, A, basisProducts, onBasis] = sys;
    const std::vector<double> exact = directSolve(K, b);
    const std::vector<float> noise = randomRhs(n, 25);
    for (int restart : {40, 3}) {
        std::vector<float> x0(n), x, ax(n), r(n);
        for (int i = 0; i < n; ++i) x0[i] = float(exact[i] * (1 + 0.01 * (noise[i] - 0.5)));
        A(x0, ax);
        for (int i = 0; i < n; ++i) r[i] = b[i] - ax[i];
        x = x0;
        const GmresReport fromGuess = solveGmres(
            A, onBasis, halfB, w, 1e-6 * bNorm, restart, [] { return true; }, x, r);
        A(x, ax);
        for (int i = 0; i < n; ++i) r[i] = b[i] - ax[i];
        EXPECT_TRUE(fromGuess.converged) << "restart " << restart;
        EXPECT_LE(std::sqrt(weightedDot(w, r, r)), 1e-6 * bNorm) << "restart " << restart;
        for (int i = 0; i < n; ++i) EXPECT_NEAR(x[i], exact[i], 1e-4 * std::fabs(exact[i])) << i;
        std::vector<float> fromZeroX, wrongX = x0;
        const GmresReport fromZero = solveGmres(
            A, onBasis, halfB, w, 1e-6 * bNorm, restart, [] { return true; }, fromZeroX);
        const GmresReport wrong = solveGmres(
            A, onBasis, halfB, w, 1e-6 * bNorm, restart, [] { return true; }, wrongX, b);
        EXPECT_LT(fromGuess.matvecs, fromZero.matvecs) << "restart " << restart;
        EXPECT_LT(fromGuess.matvecs, wrong.matvecs) << "restart " << restart;
    }
}

TEST(Gmres, WeightedInnerProductAndBudget) {
    const int n = 30;
    const auto K = makeSystem(n, 0.9, 4);
    const std::vector<float> b = randomRhs(n, 5);
    const std::vector<double> w = repeatingWeights(n, 0.5, 3);
    std::vector<float> x;
    int budget = 3;
    const GmresReport stopped = solveGmres(
        operatorOf(K), b, w, 0.0, 40, [&] { return budget-- > 0; }, x);
    EXPECT_FALSE(stopped.converged);
    EXPECT_LE(stopped.matvecs, 4);
    EXPECT_NEAR(stopped.rhsNorm * stopped.rhsNorm, weightedDot(w, b, b), 1e-9 * weightedDot(w, b, b));
    const GmresReport done = solveGmres(
        operatorOf(K), b, w, 1e-5, 40, [] { return true; }, x);
    EXPECT_TRUE(done.converged);
    EXPECT_LE(done.residualNorm, 1e-5);
}

TEST(Gmres, SameResultForAnyThreadCount) {
    const int n = 200000;  // several reduction chunks
    std::vector<float> b(n), w1, w2;
    for (int i = 0; i < n; ++i) b[i] = float(std::sin(0.001 * i) + 1.5);
    const std::vector<double> w(n, 1.0);
    const LinearOperator A = [](const std::vector<float>& x, std::vector<float>& y) {
        for (size_t i = 0; i < x.size(); ++i) y[i] = 1.25f * x[i] - 0.2f * x[(i + 1) % x.size()];
    };
    {
        ThreadLimit one(1);
        solveGmres(
            A, b, w, 1e-3, 10, [] { return true; }, w1);
    }
    {
        ThreadLimit two(2);
        solveGmres(
            A, b, w, 1e-3, 10, [] { return true; }, w2);
    }
    EXPECT_EQ(w1, w2);
}

// The weights repeat with their own length (one voxel's bins and channels): a period of 3
// gives the inner product and the solution of the same weights written out in full.
TEST(Gmres, WeightsRepeatWithTheirPeriod) {
    const int n = 30;
    const auto K = makeSystem(n, 0.9, 7);
    const std::vector<float> b = randomRhs(n, 8);
    const std::vector<double> period = {0.5, 1.5, 2.5};
    std::vector<double> full(n);
    for (int i = 0; i < n; ++i) full[i] = period[size_t(i) % period.size()];
    EXPECT_EQ(weightedDot(period, b, b), weightedDot(full, b, b));
    std::vector<float> xp, xf;
    const GmresReport rp = solveGmres(
        operatorOf(K), b, period, 1e-5, 40, [] { return true; }, xp);
    const GmresReport rf = solveGmres(
        operatorOf(K), b, full, 1e-5, 40, [] { return true; }, xf);
    EXPECT_TRUE(rp.converged);
    EXPECT_EQ(rp.matvecs, rf.matvecs);
    EXPECT_EQ(xp, xf);
}
