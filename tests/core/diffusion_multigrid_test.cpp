// The diffusion tail's multigrid preconditioner (core/diffusion_multigrid.h): each coarse
// operator is the Galerkin product of the finer one, the preconditioner is symmetric and
// positive (as CG needs), it cuts the CG's iterations on a thick cloud at albedo 0.99 to
// the same solution, the same bits at any thread count; and the operator itself reads its
// neighbours right across sparse tiles.
#include "core/diffusion_multigrid.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstring>

#include "core/parallel.h"
#include "lpm_vs_mc.h"
#include "random_field.h"
#include "test_scenes.h"

using namespace lpm;
using namespace lpm::test;

namespace {

/// sparseBlock's tiles and extinction with cubic voxels (the operator's convention).
Medium cubicSparseBlock() {
    Medium m = sparseBlock(7);
    m.voxelSize = {0.5, 0.5, 0.5};
    return m;
}

}  // namespace

// The same medium stored in tiles and densely gives the same matrix: a voxel's neighbours
// across a tile's face, in a missing tile, and at the block's edge are read right.
TEST(DiffusionOperator, SparseTilesGiveTheDenseMatrix) {
    const Medium sparse = cubicSparseBlock();
    ASSERT_TRUE(sparse.sparse());
    Medium dense;
    dense.allocate(sparse.nx, sparse.ny, sparse.nz);
    dense.voxelSize = sparse.voxelSize;
    for (int z = 0; z < sparse.nz; ++z)
        for (int y = 0; y < sparse.ny; ++y)
            for (int x = 0; x < sparse.nx; ++x) {
                const std::size_t i = sparse.index(x, y, z);
                dense.sigmaT[dense.index(x, y, z)] = i == Medium::npos ? 0.0f : sparse.sigmaT[i];
            }
    const DiffusionOperator as(sparse), ad(dense);
    const RGB albedo(0.99f, 0.9f, 0.5f);
    const std::vector<float> xd = randomField(3 * ad.voxels(), 1);
    std::vector<float> xs(3 * as.voxels(), 0.0f), ys, yd;
    for (int z = 0; z < sparse.nz; ++z)
        for (int y = 0; y < sparse.ny; ++y)
            for (int x = 0; x < sparse.nx; ++x) {
                const std::size_t i = sparse.index(x, y, z);
                if (i != Medium::npos)
                    for (std::size_t c = 0; c < 3; ++c) xs[i * 3 + c] = xd[dense.index(x, y, z) * 3 + c];
            }
    as.apply(xs, albedo, ys);
    ad.apply(xd, albedo, yd);
    int compared = 0;
    for (int z = 0; z < sparse.nz; ++z)
        for (int y = 0; y < sparse.ny; ++y)
            for (int x = 0; x < sparse.nx; ++x) {
                const std::size_t i = sparse.index(x, y, z), j = dense.index(x, y, z);
                if (i == Medium::npos || !(sparse.sigmaT[i] > 0)) continue;
                for (std::size_t c = 0; c < 3; ++c)
                    ASSERT_EQ(ys[i * 3 + c], yd[j * 3 + c]) << x << " " << y << " " << z;
                ++compared;
            }
    EXPECT_GT(compared, 3000);
}

// Each coarse level's operator is P^T A P of the level below (P: each cell its parent's
// value): checked on the first level, for a random coarse vector, per channel.
TEST(DiffusionMultigrid, CoarseOperatorIsTheGalerkinProduct) {
    const Medium m = makeVolume(VolumeKind::Cloud, 24, 40.0);
    const DiffusionOperator a(m);
    const DiffusionMultigrid mg(a);
    ASSERT_GE(mg.coarseLevels(), 1);
    const DiffusionMultigrid::Level& L = mg.level(0);
    const RGB albedo(0.99f, 0.8f, 0.3f);
    const std::vector<float> X = randomField(3 * L.cells(), 2);
    // Each fine voxel with medium and its coarse parent.
    std::vector<std::int64_t> parent(a.voxels(), -1);
    for (std::size_t v = 0; v < a.voxels(); ++v)
        if (a.hasMedium(v)) {
            int x, y, z;
            m.coord(v, x, y, z);
            parent[v] = std::int64_t(L.index(x / 2, y / 2, z / 2));
        }
    std::vector<float> PX(3 * a.voxels(), 0.0f), APX, AcX;
    for (std::size_t v = 0; v < a.voxels(); ++v)
        if (parent[v] >= 0)
            for (std::size_t c = 0; c < 3; ++c) PX[v * 3 + c] = X[std::size_t(parent[v]) * 3 + c];
    a.apply(PX, albedo, APX);
    L.apply(X, albedo, AcX);
    std::vector<double> galerkin(3 * L.cells(), 0.0);  // P^T A P X
    for (std::size_t v = 0; v < a.voxels(); ++v)
        if (parent[v] >= 0)
            for (std::size_t c = 0; c < 3; ++c) galerkin[std::size_t(parent[v]) * 3 + c] += APX[v * 3 + c];
    double worst = 0, scale = 0;
    for (std::size_t I = 0; I < L.cells(); ++I) {
        if (!L.hasMedium(I)) continue;
        for (std::size_t c = 0; c < 3; ++c) {
            worst = std::max(worst, std::fabs(galerkin[I * 3 + c] - AcX[I * 3 + c]));
            scale = std::max(scale, std::fabs(galerkin[I * 3 + c]));
        }
    }
    EXPECT_GT(scale, 0);
    EXPECT_LT(worst, 1e-4 * scale);
}

// CG needs a symmetric positive preconditioner: <M x, y> = <x, M y> and <M x, x> > 0 on a
// heterogeneous cloud with empty voxels (and on the sparse block).
TEST(DiffusionMultigrid, PreconditionerIsSymmetricAndPositive) {
    for (const Medium& m : {makeVolume(VolumeKind::Cloud, 20, 30.0), cubicSparseBlock()}) {
        const DiffusionOperator a(m);
        const DiffusionMultigrid mg(a);
        const RGB albedo(0.995f, 0.9f, 0.6f);
        std::vector<float> x = randomField(3 * a.voxels(), 3), y = randomField(3 * a.voxels(), 4), mx, my, scratch;
        for (std::size_t v = 0; v < a.voxels(); ++v)
            if (!a.hasMedium(v))
                for (std::size_t c = 0; c < 3; ++c) x[v * 3 + c] = y[v * 3 + c] = 0.0f;
        mg.precondition(x, albedo, mx, scratch);
        mg.precondition(y, albedo, my, scratch);
        const double lhs = dot(mx, y), rhs = dot(x, my);
        EXPECT_NEAR(lhs, rhs, 1e-4 * (std::fabs(lhs) + std::fabs(rhs)));
        EXPECT_GT(dot(mx, x), 0.0);
        EXPECT_GT(dot(my, y), 0.0);
    }
}

// On a thick cloud at albedo 0.99 (diffusion lengths of tens of voxels) the multigrid CG
// meets the tolerance in a fraction of the Jacobi CG's iterations, to the same solution
// within it; and gives the same bits at 1, 2 and 16 threads.
TEST(DiffusionMultigrid, CutsTheIterationsToTheSameSolution) {
    const Medium m = makeVolume(VolumeKind::Cloud, 40, 64.0);
    const DiffusionOperator a(m);
    const DiffusionMultigrid mg(a);
    const RGB albedo(0.99f, 0.97f, 0.9f);
    std::vector<float> b = randomField(3 * a.voxels(), 5);
    for (float& v : b) v = std::fabs(v);
    const DiffusionSolve jac = a.solve(b, albedo, 1e-4, 5000), pre = a.solve(b, albedo, 1e-4, 5000, &mg);
    std::printf("CG iterations to 1e-4: Jacobi %d, multigrid %d (%d coarse levels)\n", jac.iterations, pre.iterations,
                mg.coarseLevels());
    for (double r : pre.relativeResidual) EXPECT_LE(r, 1e-4);
    EXPECT_LT(3 * pre.iterations, jac.iterations);
    double num = 0, den = 0;
    for (std::size_t i = 0; i < b.size(); ++i) {
        num += (pre.J[i] - jac.J[i]) * (pre.J[i] - jac.J[i]);
        den += double(jac.J[i]) * jac.J[i];
    }
    EXPECT_LT(std::sqrt(num / den), 1e-3);
    std::vector<float> ref;
    for (int threads : {1, 2, 16}) {
        ThreadLimit limit(threads);
        const DiffusionSolve s = a.solve(b, albedo, 1e-3, 500, &mg);
        if (ref.empty()) ref = s.J;
        else EXPECT_EQ(0, std::memcmp(ref.data(), s.J.data(), ref.size() * sizeof(float))) << threads << " threads";
    }
}
