// The voxels of a medium that hold mass (sigma_t > 0), numbered as rows in storage order.
//
// A source of the solver is radiance per bin, and the sweeps emit sigma_s times it: where
// sigma_t = 0 a source has no power, whatever its value. A two-grid solve's coarse grid
// (docs/multires.md) stores whole 8^3 tiles, each covering 16^3 fine voxels, and about
// half of its stored voxels are the tiles' empty fringes (the plume-1M: 131,743 of 254,464
// hold mass). The buffers that only carry sources there (the separable fine sources'
// coarse parts, the coarse solve's unshot, next, source sum and Krylov vectors) hold one
// row per voxel with mass (docs/multires.md, "Rows with mass").
#pragma once

#include <cstddef>
#include <cstdint>
#include <vector>

#include "core/medium.h"

namespace lpm {

struct MassRows {
    static constexpr std::uint32_t kNone = ~std::uint32_t(0);
    std::vector<std::uint32_t> rowOf;  ///< [stored voxel] its row, kNone without mass
    std::vector<std::uint32_t> voxel;  ///< [row] its stored voxel (increasing)

    MassRows() = default;
    explicit MassRows(const Medium& m);
    size_t size() const { return voxel.size(); }
};

/// x [row][width] at its rows' voxels: [stored voxel][width], 0 at the voxels without mass.
std::vector<float> expandRows(const MassRows& rows, const std::vector<float>& x, size_t width);
/// The rows of x [stored voxel][width]: [row][width].
std::vector<float> gatherRows(const MassRows& rows, const std::vector<float>& x, size_t width);

}  // namespace lpm
