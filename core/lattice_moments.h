// The ray lattice's sampling of a voxel's lateral coordinate through one slice: what the
// linear source's sweeps (core/sweep_reference.cpp, core/sweep.cpp) correct their
// positions and moments by (docs/lpm_solver.md, "Linear source").
#pragma once

#include <algorithm>
#include <cmath>

namespace lpm {

// How the r x r ray lattice of one direction samples the lateral coordinate of the voxels
// of slice t. At depth s in [0, 1] of the slice the rays in any voxel sit at
// xi = delta(s) + (j - (r-1)/2) / r, j = 0..r-1, delta(s) = (frac(o + r d (t + s)) - 1/2) / r
// (o the lattice offset, d the lateral shift per slice in voxels), the same for every
// voxel of the slice. Their centroid over the slice is Int delta ds, their spread about it
// (r^2 - 1) / (12 r^2) + Int delta^2 ds - centroid^2; the uniform values are 0 and 1/12.
struct LatticeMoments {
    double centroid = 0, scale = 1;  // scale = (1/12) / spread
    LatticeMoments() = default;
    LatticeMoments(double o, double d, int r, int t) {
        // Antiderivatives of frac(x) - 1/2 and (frac(x) - 1/2)^2.
        auto G1 = [](double x) {
            const double f = x - std::floor(x);
            return 0.5 * f * f - 0.5 * f;
        };
        auto G2 = [](double x) {
            const double fl = std::floor(x), f = x - fl, h = f - 0.5;
            return fl / 12 + (h * h * h + 0.125) / 3;
        };
        const double x0 = o + r * d * t, D = r * d;
        double m1, m2;
        if (std::fabs(D) < 1e-7) {
            const double g = (x0 + 0.5 * D) - std::floor(x0 + 0.5 * D) - 0.5;
            m1 = g;
            m2 = g * g;
        } else {
            // G1 is periodic (frac - 1/2 integrates to zero over a period).
            m1 = (G1(x0 + D) - G1(x0)) / D;
            m2 = (G2(x0 + D) - G2(x0)) / D;
        }
        centroid = m1 / r;
        const double spread = (double(r) * r - 1) / (12.0 * r * r) + std::max(0.0, m2 - m1 * m1) / (double(r) * r);
        scale = spread > 0 ? (1.0 / 12) / spread : 1.0;
    }
};

}  // namespace lpm
