// Separable fine sources (core/separable_source.h): what the form keeps exactly (each
// fine voxel's angular integral, the sigma-weighted restriction, the source power), what
// its fold computes (the full fold's SH and bins, reduced), and that a bake with it stays
// with the full form against Monte Carlo.
#include "core/separable_source.h"

#include <gtest/gtest.h>

#include <cmath>

#include "core/half_buffer.h"
#include "core/multires.h"
#include "core/parallel.h"
#include "core/rng.h"
#include "core/sweep.h"
#include "lpm_vs_mc.h"

using namespace lpm;
using namespace lpm::test;

namespace {

/// Band-0 relative RMS of a against b over the voxels where b is above `floor` x its largest value.
double band0Difference(const LpmResult& a, const LpmResult& b, size_t voxels, double floor) {
    double peak = 0, num = 0, den = 0;
    for (size_t v = 0; v < voxels; ++v) peak = std::max(peak, double(b.coeff(v, 0)[0]));
    for (size_t v = 0; v < voxels; ++v)
        for (int c = 0; c < 3; ++c) {
            const double x = a.coeff(v, 0)[c], y = b.coeff(v, 0)[c];
            if (y < floor * peak) continue;
            num += (x - y) * (x - y);
            den += y * y;
        }
    return std::sqrt(num / den);
}

bool insideBlock(const Medium& m, size_t v) {
    int x, y, z;
    m.coord(v, x, y, z);
    return x >= 0 && x < m.nx && y < m.ny && z < m.nz;
}

/// sparseBlock with no extinction for x < 10: its coarse voxels with x < 5 hold no mass
/// (no row in the map), while elsewhere single fine voxels without extinction remain.
Medium blockWithEmptySlab(std::uint64_t seed) {
    Medium m = sparseBlock(seed);
    for (size_t v = 0; v < m.voxelCount(); ++v) {
        int x, y, z;
        m.coord(v, x, y, z);
        if (x < 10) m.sigmaT[v] = 0.0f;
    }
    return m;
}

/// x [row][width] of map's rows at their coarse voxels ([coarse voxel][width], 0 elsewhere).
std::vector<float> atCoarseVoxels(const FineCoarseMap& map, const std::vector<float>& x, size_t width) {
    return expandRows(map.coarseRows, x, width);
}

// Random jobs (bin and SH coefficients) and their random deposits: a pass's fold input.
struct FoldInput {
    int bins = 5, coeffs = 4;
    std::vector<double> binWeight;
    std::vector<Job> jobs;
    std::vector<std::vector<float>> phi;  // [job][voxel][rgb]
    FoldInput(const Medium& m, size_t n, std::uint64_t seed, int shCoeffs = 4) : coeffs(shCoeffs) {
        Pcg32 rng(seed, 3);
        for (int d = 0; d < bins; ++d) binWeight.push_back(0.5 + rng.uniform());
        for (size_t j = 0; j < n; ++j) {
            Job job;
            for (int d = 0; d < bins; ++d) job.binCoef.push_back(rng.uniform() < 0.4 ? 0.0 : rng.uniform());
            for (int k = 0; k < coeffs; ++k) job.shCoef.push_back(rng.uniform() - 0.3);
            jobs.push_back(job);
            std::vector<float> p(m.voxelCount() * 3, 0.0f);
            for (size_t v = 0; v < m.voxelCount(); ++v)
                if (insideBlock(m, v) && rng.uniform() < 0.9)
                    for (int c = 0; c < 3; ++c) p[v * 3 + c] = float(rng.uniform());
            phi.push_back(std::move(p));
        }
    }
    // The full fold's next source [voxel][bin][rgb] and SH [voxel][coeff][rgb].
    void fullFold(size_t N, std::vector<float>& U, std::vector<float>& sh) const {
        U.assign(N * bins * 3, 0.0f);
        sh.assign(N * coeffs * 3, 0.0f);
        for (size_t v = 0; v < N; ++v)
            for (size_t j = 0; j < jobs.size(); ++j)
                for (int c = 0; c < 3; ++c) {
                    const double p = phi[j][v * 3 + c];
                    for (int d = 0; d < bins; ++d) U[(v * bins + d) * 3 + c] += float(jobs[j].binCoef[d] * p);
                    for (int k = 0; k < coeffs; ++k) sh[(v * coeffs + k) * 3 + c] += float(jobs[j].shCoef[k] * p);
                }
    }
};

SeparableSource foldSeparably(const Medium& f, const FineCoarseMap& map, const FoldInput& in, std::vector<float>& sh,
                              size_t batch, const HalfBuffer* minus = nullptr,
                              const std::vector<float>* minusIsotropic = nullptr) {
    SeparableFold fold(map, f.sigmaT, in.binWeight, in.coeffs);
    sh.assign(f.voxelCount() * in.coeffs * 3, 0.0f);
    for (size_t b0 = 0; b0 < in.jobs.size(); b0 += batch) {
        const size_t n = std::min(batch, in.jobs.size() - b0);
        std::vector<std::vector<float>> phi(in.phi.begin() + long(b0), in.phi.begin() + long(b0 + n));
        fold.fold(true, &in.jobs[b0], n, phi, sh);
    }
    return fold.finish(minus, minusIsotropic);
}

// The separable fold of `in` in batches of 3, 4 and 7 jobs against the full fold's SH,
// integrals and restriction.
void expectFoldsMatch(const Medium& f, const FineCoarseMap& map, const FoldInput& in, const std::vector<float>& U,
                      const std::vector<float>& shFull, const std::vector<float>& restrictedFull) {
    for (size_t batch : {size_t(3), size_t(4), size_t(7)}) {
        SCOPED_TRACE(batch);
        std::vector<float> sh;
        const SeparableSource s = foldSeparably(f, map, in, sh, batch);
        for (size_t i = 0; i < sh.size(); ++i) ASSERT_NEAR(sh[i], shFull[i], 1e-5f * (1 + std::fabs(shFull[i]))) << i;
        // Under a parent without mass (no row) the integral is not formed: 0.
        for (size_t v = 0; v < f.voxelCount(); ++v)
            for (int ch = 0; ch < 3; ++ch) {
                double m = 0;
                for (int d = 0; d < in.bins; ++d) m += in.binWeight[d] * U[(v * in.bins + d) * 3 + ch];
                if (map.parent[v] == FineCoarseMap::kNone) m = 0;
                ASSERT_NEAR(s.magnitude[v * 3 + ch], m, 1e-5 * (1 + m)) << v;
            }
        // R_C is held in half precision: within 2^-11 of each value (core/half_buffer.h).
        const std::vector<float> r = atCoarseVoxels(map, s.restricted(), size_t(in.bins) * 3);
        ASSERT_EQ(r.size(), restrictedFull.size());
        for (size_t i = 0; i < r.size(); ++i)
            ASSERT_NEAR(r[i], restrictedFull[i],
                        1e-5f * (1 + restrictedFull[i]) + std::ldexp(1.0f, -11) * std::fabs(restrictedFull[i]))
                << i;
    }
}

}  // namespace

// Every fine voxel of the block is paired with its parent's row, and only the coarse
// voxels that hold mass have rows, in storage order.
TEST(SeparableSource, MapPairsEveryFineVoxelOfTheBlockWithItsParentsRow) {
    const Medium f = blockWithEmptySlab(3);
    const Medium c = coarsen(f);
    const FineCoarseMap map(f, c);
    const std::vector<std::uint32_t>& rowOf = map.coarseRows.rowOf;
    ASSERT_EQ(rowOf.size(), c.voxelCount());
    ASSERT_EQ(map.sigmaSum.size(), map.rows());
    for (size_t row = 0; row < map.rows(); ++row) {
        const std::uint32_t ci = map.coarseRows.voxel[row];
        if (row > 0) {
            ASSERT_LT(map.coarseRows.voxel[row - 1], ci);
        }
        ASSERT_EQ(rowOf[ci], row);
        EXPECT_NEAR(map.sigmaSum[row], 8 * c.sigmaT[ci], 1e-4) << row;
    }
    size_t withMass = 0;
    for (size_t ci = 0; ci < c.voxelCount(); ++ci) {
        withMass += c.sigmaT[ci] > 0;
        EXPECT_EQ(rowOf[ci] != FineCoarseMap::kNone, c.sigmaT[ci] > 0) << ci;
    }
    EXPECT_EQ(map.rows(), withMass);
    EXPECT_LT(map.rows(), c.voxelCount() * 9 / 10);  // the empty slab has no rows
    size_t mapped = 0, zeroUnderMass = 0;
    for (size_t v = 0; v < f.voxelCount(); ++v) {
        const std::uint32_t p = map.parent[v];
        int x, y, z;
        f.coord(v, x, y, z);
        const size_t ci = insideBlock(f, v) ? c.index(x / 2, y / 2, z / 2) : Medium::npos;
        ASSERT_EQ(p, ci == Medium::npos ? FineCoarseMap::kNone : rowOf[ci]) << v;
        if (p == FineCoarseMap::kNone) {
            if (insideBlock(f, v)) {
                EXPECT_EQ(f.sigmaT[v], 0.0f) << v;
            }
            continue;
        }
        ++mapped;
        zeroUnderMass += f.sigmaT[v] == 0;
        EXPECT_EQ(map.children[size_t(p) * 8 + size_t((x & 1) + 2 * (y & 1) + 4 * (z & 1))], v);
    }
    EXPECT_GT(zeroUnderMass, size_t(0));
    size_t children = 0;
    for (std::uint32_t ch : map.children) children += ch != FineCoarseMap::kNone;
    EXPECT_EQ(children, mapped);
}

// The separable fold computes the full fold's SH exactly (same order of sums), also where
// no mass is near (the written shell of a density), and, of its next source, each voxel's
// angular integral and the sigma-weighted restriction (restrictSource of the full source),
// for any batch size; with 9 SH coefficients (order 2) batches of 4 take the unrolled
// kernel (foldFineRange4x9), the others the general one.
TEST(SeparableSource, FoldKeepsTheFullFoldsIntegralsAndRestriction) {
    for (int coeffs : {4, 9}) {
        SCOPED_TRACE(coeffs);
        const Medium f = blockWithEmptySlab(4);
        const Medium c = coarsen(f);
        const FineCoarseMap map(f, c);
        const FoldInput in(f, 7, 5, coeffs);
        std::vector<float> U, shFull;
        in.fullFold(f.voxelCount(), U, shFull);
        const std::vector<float> restrictedFull = restrictSource(f, c, U, in.bins, 1);
        expectFoldsMatch(f, map, in, U, shFull, restrictedFull);
    }
}

// Deposits held in bfloat16 (the passes after pass 0) fold as the floats they hold: the
// same SH, integrals and restriction, bit for bit, with either kernel (9 coefficients in
// batches of 4: foldFineRange4x9) and any batch.
TEST(SeparableSource, Bf16DepositsFoldAsTheFloatsTheyHold) {
    for (int coeffs : {4, 9})
        for (size_t batch : {size_t(3), size_t(4)}) {
            SCOPED_TRACE(testing::Message() << coeffs << " coefficients, batches of " << batch);
            const Medium f = blockWithEmptySlab(4);
            const FineCoarseMap map(f, coarsen(f));
            FoldInput in(f, 7, 13, coeffs);
            std::vector<std::vector<Bf16>> held;
            for (std::vector<float>& p : in.phi) {
                held.emplace_back(p.size());
                for (size_t i = 0; i < p.size(); ++i) {
                    held.back()[i] = bf16FromFloat(p[i]);
                    p[i] = floatFromBf16(held.back()[i]);
                }
            }
            SeparableFold fromFloat(map, f.sigmaT, in.binWeight, in.coeffs),
                fromBf16(map, f.sigmaT, in.binWeight, in.coeffs);
            std::vector<float> shFloat(f.voxelCount() * size_t(coeffs) * 3, 0.0f), shBf16 = shFloat;
            for (size_t b0 = 0; b0 < in.jobs.size(); b0 += batch) {
                const size_t n = std::min(batch, in.jobs.size() - b0);
                fromFloat.fold(
                    true, &in.jobs[b0], n,
                    std::vector<std::vector<float>>(in.phi.begin() + long(b0), in.phi.begin() + long(b0 + n)), shFloat);
                fromBf16.fold(true, &in.jobs[b0], n,
                              std::vector<std::vector<Bf16>>(held.begin() + long(b0), held.begin() + long(b0 + n)),
                              shBf16);
            }
            EXPECT_TRUE(shFloat == shBf16);
            const SeparableSource a = fromFloat.finish(), b = fromBf16.finish();
            EXPECT_TRUE(a.magnitude == b.magnitude);
            EXPECT_TRUE(a.shape.bits == b.shape.bits);
            EXPECT_TRUE(a.norm == b.norm);
            EXPECT_GT(*std::max_element(shBf16.begin(), shBf16.end()), 0.1f);  // not an empty fold
        }
}

// finish(&P) takes a coarse part P from the folded source as it forms it (the two-grid
// cycle's r' = K E - tail): the restriction is the plain fold's less P (to within R_C's
// rounding), every fine voxel's angular integral its m_f less P's, no offset is left, and
// the power is that of the plain fold holding -P as its offset.
TEST(SeparableSource, FinishTakesAPartFromTheRestrictionAndEveryIntegral) {
    const Medium f = blockWithEmptySlab(9);
    const Medium c = coarsen(f);
    const FineCoarseMap map(f, c);
    const FoldInput in(f, 6, 4);
    Pcg32 rng(10, 4);
    std::vector<float> part(map.rows() * in.bins * 3), negated(part.size());
    for (size_t i = 0; i < part.size(); ++i) {
        part[i] = 0.8f * (float(rng.uniform()) - 0.4f);
        negated[i] = -part[i];
    }
    const HalfBuffer partHeld = SeparableSource::holdByBin(part, in.bins);
    std::vector<float> sh;
    SeparableSource plain = foldSeparably(f, map, in, sh, 4);
    const SeparableSource taken = foldSeparably(f, map, in, sh, 4, &partHeld);
    EXPECT_TRUE(taken.offset.empty());
    const std::vector<float> rPlain = plain.restricted(), rTaken = taken.restricted();
    ASSERT_EQ(rPlain.size(), rTaken.size());
    std::vector<double> partIntegral(map.rows() * 3, 0.0);
    for (size_t p = 0; p < map.rows(); ++p)
        for (int d = 0; d < in.bins; ++d)
            for (int ch = 0; ch < 3; ++ch) {
                const size_t i = (p * size_t(in.bins) + size_t(d)) * 3 + size_t(ch);
                const float held = partHeld.at(plain.heldIndex(p, size_t(d), size_t(ch)));
                partIntegral[p * 3 + size_t(ch)] += in.binWeight[size_t(d)] * held;
                const float want = rPlain[i] - held;
                ASSERT_NEAR(rTaken[i], want, std::ldexp(1.0f, -10) * (std::fabs(rPlain[i]) + std::fabs(held)) + 1e-6f)
                    << "row " << p << " bin " << d;
            }
    size_t under = 0;
    for (size_t v = 0; v < f.voxelCount(); ++v)
        for (int ch = 0; ch < 3; ++ch) {
            const std::uint32_t p = map.parent[v];
            const double want =
                plain.magnitude[v * 3 + ch] - (p == FineCoarseMap::kNone ? 0.0 : partIntegral[p * 3 + ch]);
            ASSERT_NEAR(taken.magnitude[v * 3 + ch], want, 1e-5 * (1 + std::fabs(want))) << "voxel " << v;
            under += p != FineCoarseMap::kNone && ch == 0;
        }
    EXPECT_GT(under, f.voxelCount() / 4);
    plain.offset.push_back(SeparableSource::holdByBin(negated, in.bins));
    const RGB albedo(0.9f, 0.8f, 0.7f);
    const double want = plain.power(map, in.binWeight, albedo, f.voxelVolume());
    EXPECT_NEAR(taken.power(map, in.binWeight, albedo, f.voxelVolume()), want, std::ldexp(1.0, -10) * std::fabs(want));
    SeparableFold wrong(map, f.sigmaT, in.binWeight, in.coeffs);
    const HalfBuffer short_ = SeparableSource::holdByBin(std::vector<float>(in.bins * 3, 1.0f), in.bins);
    EXPECT_THROW(wrong.finish(&short_), Error);
}

// An isotropic part t_f per fine voxel (the diffusion tail, core/diffusion_cycle.cpp):
// fillBin adds it to every bin of the voxel, and finish takes it from the folded source by
// its children's sigma-weighted mean in every bin of R_C and by W t_f from each m_f, so the
// restriction and every integral of K E - t stay exact. Sources holding one have no
// power() (the cycle measures r, not E); a part of the wrong size is named.
TEST(SeparableSource, IsotropicPartIsFilledIntoEveryBinAndTakenExactly) {
    const Medium f = blockWithEmptySlab(9);
    const Medium c = coarsen(f);
    const FineCoarseMap map(f, c);
    const FoldInput in(f, 6, 4);
    Pcg32 rng(12, 5);
    std::vector<float> t(f.voxelCount() * 3, 0.0f);
    for (size_t v = 0; v < f.voxelCount(); ++v)
        if (map.parent[v] != FineCoarseMap::kNone)
            for (int ch = 0; ch < 3; ++ch) t[v * 3 + ch] = 0.6f * (float(rng.uniform()) - 0.3f);
    std::vector<float> sh;
    const SeparableSource plain = foldSeparably(f, map, in, sh, 4);
    const SeparableSource taken = foldSeparably(f, map, in, sh, 4, nullptr, &t);
    EXPECT_TRUE(taken.isotropic.empty());
    double W = 0;
    for (double w : in.binWeight) W += float(w);
    for (size_t v = 0; v < f.voxelCount(); ++v)
        for (int ch = 0; ch < 3; ++ch) {
            const double want = plain.magnitude[v * 3 + ch] - W * t[v * 3 + ch];
            ASSERT_NEAR(taken.magnitude[v * 3 + ch], want, 1e-5 * (1 + std::fabs(want))) << "voxel " << v;
        }
    const std::vector<float> rPlain = plain.restricted(), rTaken = taken.restricted();
    size_t checked = 0;
    for (size_t p = 0; p < map.rows(); ++p)
        for (int ch = 0; ch < 3; ++ch) {
            double sum = 0;
            for (int k = 0; k < 8; ++k) {
                const std::uint32_t kid = map.children[p * 8 + size_t(k)];
                if (kid != FineCoarseMap::kNone) sum += double(f.sigmaT[kid]) * t[size_t(kid) * 3 + size_t(ch)];
            }
            const double mean = sum / map.sigmaSum[p];
            for (int d = 0; d < in.bins; ++d) {
                const size_t i = (p * size_t(in.bins) + size_t(d)) * 3 + size_t(ch);
                const double want = rPlain[i] - mean;
                ASSERT_NEAR(rTaken[i], want, std::ldexp(1.0, -10) * (std::fabs(rPlain[i]) + std::fabs(mean)) + 1e-6)
                    << "row " << p << " bin " << d;
                ++checked;
            }
        }
    EXPECT_GT(checked, size_t(100));
    // Filled: the plain source's value plus t_f in every bin, 0 outside the parents.
    SeparableSource withPart = foldSeparably(f, map, in, sh, 4);
    withPart.isotropic = t;
    std::vector<float> a(f.voxelCount() * 3), b(f.voxelCount() * 3);
    for (int d = 0; d < in.bins; ++d) {
        plain.fillBin(map, d, a.data());
        withPart.fillBin(map, d, b.data());
        for (size_t i = 0; i < a.size(); ++i) ASSERT_NEAR(b[i] - a[i], t[i], 1e-5f * (1 + std::fabs(a[i]))) << i;
    }
    EXPECT_THROW(withPart.power(map, in.binWeight, RGB(0.9f), f.voxelVolume()), Error);
    EXPECT_THROW(withPart.absolutePower(f.sigmaT, RGB(0.9f), f.voxelVolume()), Error);
    SeparableFold wrong(map, f.sigmaT, in.binWeight, in.coeffs);
    const std::vector<float> short_(3, 1.0f);
    EXPECT_THROW(wrong.finish(nullptr, &short_), Error);
}

// Reconstruction: every fine voxel's angular integral is its magnitude, exactly, though
// R_C is held in half precision; a source whose angular shape is constant within each
// coarse voxel comes back to within R_C's rounding (2^-11 of each bin's value, twice over
// with the normalisation); the power, with a coarse offset of two half-precision parts, is
// that of the full source with their sum injected, to within the same rounding.
// Filled into bfloat16, each value is the float fill rounded (core/bf16.h).
TEST(SeparableSource, FillBinReconstructsIntegralsShapesAndPower) {
    const Medium f = blockWithEmptySlab(6);
    const Medium c = coarsen(f);
    const FineCoarseMap map(f, c);
    const int bins = 4;
    const std::vector<double> w = {0.7, 1.1, 0.9, 1.3};
    Pcg32 rng(8, 2);
    std::vector<float> shapeC(map.rows() * bins * 3), U(f.voxelCount() * bins * 3, 0.0f);
    for (float& x : shapeC) x = float(rng.uniform());
    for (size_t v = 0; v < f.voxelCount(); ++v) {
        if (map.parent[v] == FineCoarseMap::kNone) continue;
        const float a = float(rng.uniform());
        for (int d = 0; d < bins; ++d)
            for (int ch = 0; ch < 3; ++ch) U[(v * bins + d) * 3 + ch] = a * shapeC[(map.parent[v] * bins + d) * 3 + ch];
    }
    // Fold U through one job per bin with unit deposits scaled by U: binCoef = one-hot.
    FoldInput in(f, 0, 1);
    in.bins = bins;
    in.coeffs = 1;
    in.binWeight = w;
    for (int d = 0; d < bins; ++d) {
        Job job;
        job.binCoef.assign(bins, 0.0);
        job.binCoef[d] = 1.0;
        job.shCoef = {0.0};
        in.jobs.push_back(job);
        std::vector<float> p(f.voxelCount() * 3);
        for (size_t v = 0; v < f.voxelCount(); ++v)
            for (int ch = 0; ch < 3; ++ch) p[v * 3 + ch] = U[(v * bins + d) * 3 + ch];
        in.phi.push_back(std::move(p));
    }
    std::vector<float> sh;
    SeparableSource s = foldSeparably(f, map, in, sh, 2);
    std::vector<float> tail(map.rows() * bins * 3), previous(tail.size());
    for (float& x : tail) x = float(rng.uniform()) - 0.3f;
    for (float& x : previous) x = 10.0f * (float(rng.uniform()) - 0.7f);
    s.offset.push_back(SeparableSource::holdByBin(previous, bins));
    s.offset.push_back(SeparableSource::holdByBin(tail, bins));
    std::vector<float> offsetSum(tail.size());
    for (size_t p = 0; p < map.rows(); ++p)
        for (int d = 0; d < bins; ++d)
            for (int ch = 0; ch < 3; ++ch) {
                const size_t i = (p * bins + size_t(d)) * 3 + size_t(ch), h = s.heldIndex(p, size_t(d), size_t(ch));
                offsetSum[i] = s.offset[0].at(h) + s.offset[1].at(h);
                ASSERT_EQ(s.offsetAt(h), offsetSum[i]) << i;
                ASSERT_NEAR(offsetSum[i], previous[i] + tail[i], 11.0 / 2048) << i;  // half: 2^-11 relative
            }
    std::vector<float> withTail = U;
    addCoarse(f, c, atCoarseVoxels(map, offsetSum, size_t(bins) * 3), bins, 1, 1.0f, withTail);
    std::vector<float> out(f.voxelCount() * 3);
    std::vector<double> integral(f.voxelCount() * 3, 0.0);
    std::vector<Bf16> out16(out.size(), bf16FromFloat(3.0f));
    for (int d = 0; d < bins; ++d) {
        s.fillBin(map, d, out.data());
        // The bfloat16 fill (the separable passes' bin source) stores each value rounded.
        s.fillBin(map, d, out16.data());
        for (size_t i = 0; i < out.size(); ++i) ASSERT_EQ(out16[i].bits, bf16FromFloat(out[i]).bits) << i;
        for (size_t v = 0; v < f.voxelCount(); ++v)
            for (int ch = 0; ch < 3; ++ch) {
                // Under a coarse voxel with no extinction the shape is unknown (0): a source
                // there has no power.
                if (map.parent[v] == FineCoarseMap::kNone || !(map.sigmaSum[map.parent[v]] > 0)) continue;
                const float want = withTail[(v * bins + d) * 3 + ch];
                const float shaped = U[(v * bins + d) * 3 + ch];
                ASSERT_NEAR(out[v * 3 + ch], want, 2e-5f * (1 + std::fabs(want)) + std::ldexp(1.0f, -10) * shaped)
                    << v << " bin " << d;
                integral[v * 3 + ch] += w[d] * (out[v * 3 + ch] - offsetSum[(map.parent[v] * bins + d) * 3 + ch]);
            }
    }
    size_t checked = 0;
    for (size_t v = 0; v < f.voxelCount(); ++v) {
        if (map.parent[v] == FineCoarseMap::kNone || !(map.sigmaSum[map.parent[v]] > 0)) continue;
        ++checked;
        for (int ch = 0; ch < 3; ++ch) ASSERT_NEAR(integral[v * 3 + ch], s.magnitude[v * 3 + ch], 1e-5) << v;
    }
    EXPECT_GT(checked, f.voxelCount() / 4);  // a third of the block is the empty slab
    const RGB albedo(0.9f, 0.8f, 0.7f);
    double want = 0;
    for (size_t v = 0; v < f.voxelCount(); ++v)
        for (int d = 0; d < bins; ++d)
            for (int ch = 0; ch < 3; ++ch)
                want += double(withTail[(v * bins + d) * 3 + ch]) * f.sigmaT[v] * albedo[ch] * w[d] * f.voxelVolume();
    want /= 3;
    EXPECT_NEAR(s.power(map, w, albedo, f.voxelVolume()), want, std::ldexp(1.0, -11) * std::fabs(want));
}

// The power of a source over many coarse voxels (its sum is taken in parallel runs): the
// in-order sum of the restricted source to double rounding, and the same bits for 1 and
// 2 threads.
TEST(SeparableSource, PowerOfALargeSourceIsTheSumForAnyThreadCount) {
    Medium f;
    f.allocate(64, 48, 40);
    f.voxelSize = {0.5, 0.5, 0.5};
    Pcg32 rng(21, 4);
    for (float& s : f.sigmaT) s = float(2 * rng.uniform());
    const Medium c = coarsen(f);
    const FineCoarseMap map(f, c);
    ASSERT_GT(map.sigmaSum.size(), size_t(8192));
    const int bins = 3;
    const std::vector<double> w = {0.7, 1.1, 1.3};
    std::vector<float> shape(map.sigmaSum.size() * bins * 3), tail(shape.size());
    for (float& x : shape) x = float(rng.uniform());
    for (float& x : tail) x = float(rng.uniform()) - 0.4f;
    SeparableSource s;
    s.bins = bins;
    s.coarseRows = map.rows();
    s.shape = SeparableSource::holdByBin(shape, bins);
    s.offset.push_back(SeparableSource::holdByBin(tail, bins));
    const RGB albedo(0.9f, 0.8f, 0.7f);
    const std::vector<float> r = s.restricted();
    ASSERT_EQ(r.size(), map.rows() * bins * 3);
    // Held bin-major, restricted in the solver's order [row][bin][rgb]: each value the
    // rounded shape plus the rounded tail of the same row, bin and channel.
    for (size_t i = 0; i < r.size(); ++i) ASSERT_NEAR(r[i], shape[i] + tail[i], std::ldexp(1.0f, -10)) << i;
    double want = 0;
    for (size_t row = 0; row < map.rows(); ++row)
        for (int d = 0; d < bins; ++d)
            for (int ch = 0; ch < 3; ++ch)
                want += double(r[(row * bins + d) * 3 + ch]) * map.sigmaSum[row] * albedo[ch] * w[size_t(d)];
    want *= f.voxelVolume() / 3.0;
    double one = 0, two = 0;
    {
        ThreadLimit limit(1);
        one = s.power(map, w, albedo, f.voxelVolume());
    }
    {
        ThreadLimit limit(2);
        two = s.power(map, w, albedo, f.voxelVolume());
    }
    EXPECT_NEAR(one, want, 1e-12 * std::fabs(want));
    EXPECT_EQ(one, two);
}

// A bake with separable fine sources (auto with unshot bins and the two-grid solve) keeps
// the energy balance, is the same for 1 and 2 threads, and stays within 0.25% band-0 RMS of
// the full sources (the expensive path) against Monte Carlo on a heterogeneous plume (sky
// + sun, g = 0.5, albedo 0.95), whose shadows vary inside coarse voxels.
TEST(SeparableSource, BakeStaysWithFullSourcesAgainstMonteCarlo) {
    Case cs{"plume g0.5 a0.95", VolumeKind::Plume, 0.5, 0.95, 8.0};
    Scene sc = makeScene(cs, 32);
    sc.lights.env = &sc.sky;
    LpmSettings sep, full;
    sep.multires = full.multires = 1;
    full.separableSource = 0;
    LpmResult rs;
    {
        ThreadLimit one(1);
        rs = solveLpm(sc.medium, sc.lights, sep);
    }
    const LpmResult rs2 = solveLpm(sc.medium, sc.lights, sep);
    const LpmResult rf = solveLpm(sc.medium, sc.lights, full);
    EXPECT_TRUE(saidDecision(rs, "separable fine sources"));
    EXPECT_FALSE(saidDecision(rf, "separable fine sources"));
    EXPECT_TRUE(rs.sh == rs2.sh) << "1 and 2 threads differ";
    EXPECT_TRUE(rs.converged);
    EXPECT_NEAR(rs.absorbed + rs.escaped + rs.unshot, rs.injected, 1e-3 * rs.injected);
    const std::vector<McVoxelEstimate> mc = mcVoxelSH(sc.medium, sc.lights, sampleVoxels(sc.medium, 48), 20000, 2);
    const Comparison es = compare(rs, mc), ef = compare(rf, mc);
    std::printf("band-0 RMS vs MC: separable %.4f, full %.4f (MC noise %.4f); SH bands 1-2 RMS %.4f / %.4f\n",
                es.band0Rms, ef.band0Rms, ef.band0Noise, es.band12Rms, ef.band12Rms);
    EXPECT_LT(es.band0Rms, ef.band0Rms + 0.0025);
    EXPECT_LT(std::fabs(es.band0Bias), 0.01);
    // Against the expensive path directly, over the voxels with S above 1% of the largest.
    const double d = band0Difference(rs, rf, sc.medium.voxelCount(), 0.01);
    std::printf("band-0 relative RMS, separable against full sources: %.3g\n", d);
    EXPECT_LT(d, 5e-3);
}

namespace {

/// The 32^3 scene of `cs` under the sky and sun, solved two-grid with separable fine
/// sources (`separable`) and with full ones (`full`), both with the flat tail (separable
/// sources keep it; core/tail_shape.h).
struct SeparableAndFull {
    LpmSettings settings;
    size_t voxels = 0;
    LpmResult separable, full;
    explicit SeparableAndFull(const Case& cs) {
        Scene sc = makeScene(cs, 32);
        sc.lights.env = &sc.sky;
        LpmSettings fullSettings;
        settings.multires = fullSettings.multires = 1;
        fullSettings.separableSource = 0;
        fullSettings.shapedCoarseTail = 0;
        voxels = sc.medium.voxelCount();
        separable = solveLpm(sc.medium, sc.lights, settings);
        full = solveLpm(sc.medium, sc.lights, fullSettings);
    }
    /// Separable sources were used, converged below the tolerance, keep the energy balance
    /// and stay within 5e-3 band-0 relative RMS of full sources.
    void expectConvergedNearFull() const {
        EXPECT_TRUE(saidDecision(separable, "separable fine sources"));
        std::printf("residual: separable %.3g, full %.3g\n", separable.residual, full.residual);
        EXPECT_TRUE(separable.converged);
        EXPECT_LT(separable.residual, settings.tolerance);
        EXPECT_NEAR(separable.absorbed + separable.escaped + separable.unshot, separable.injected,
                    2e-3 * separable.injected);
        const double d = band0Difference(separable, full, voxels, 0.0);
        std::printf("band-0 relative RMS, separable against full sources: %.3g\n", d);
        EXPECT_LT(d, 5e-3);
    }
};

}  // namespace

// A thick cloud at albedo 0.99 (GMRES on the coarse grid): the two-grid cycle's residuals
// change sign, and the separable form must stay linear there (a shape divided by a signed
// angular integral lost those sources and stalled the cycle above the tolerance on the
// 1M-voxel cumulus). It converges and stays within 5e-3 of full sources.
TEST(SeparableSource, ThickHighAlbedoCycleConverges) {
    const SeparableAndFull r(Case{"cloud g0.6 a0.99", VolumeKind::Cloud, 0.6, 0.99, 30.0});
    EXPECT_TRUE(saidDecision(r.separable, "coarse grid: Krylov (GMRES) acceleration"));
    r.expectConvergedNearFull();
}

// A cloud whose coarse voxels are optically thick enough for the coarse plan to keep
// slopes (a linear source) while the fine voxels keep a constant one: the coarse solve is
// then swept by voxel, its input expanded from the coarse rows with mass and its source
// sum gathered back (core/two_grid.cpp). It converges, keeps the energy balance and stays
// within 5e-3 of full sources.
TEST(SeparableSource, LinearCoarseSourceIsSweptByVoxel) {
    const SeparableAndFull r(Case{"cloud g0.6 a0.95", VolumeKind::Cloud, 0.6, 0.95, 30.0});
    ASSERT_TRUE(saidDecision(r.separable, "coarse grid: linear source"));
    r.expectConvergedNearFull();
}
