// Where a solve holds each stored voxel's SH result (its row of coeffs x RGB floats).
//
// A bake writes S only on the density's active voxels and the one-voxel shell a trilinear
// lookup reads around them (docs/output_format.md, "Topology"); the rest of the stored
// 8^3 tiles only carries light. At SH order 2 a row is 108 B: on the 1M-voxel plume 27%
// of the stored voxels (1.53M stored, 1.11M written) held 43 MiB of rows nobody reads.
// With Medium::wantedS set, the solve keeps rows only for the wanted voxels, in storage
// order (row(v) is increasing in v), folds into them through row(), and expands the
// result to one row per stored voxel when it returns (unwanted rows 0), so a caller
// indexes the result by stored voxel; unless it asks for the rows (LpmSettings::
// keepShRows: the bake's writer reads them through LpmResult::shRow and frees them once
// its grids hold them, so the write never holds 1.53M rows of 108 B).
//
// Only directional results are compacted (coeffs > 1): at order 0 a row is 12 B and the
// isotropic fold adds to the result as one flat array.
#pragma once

#include <cstdint>
#include <vector>

#include "core/medium.h"

namespace lpm {

class ShRows {
public:
    static constexpr std::uint32_t kNone = ~std::uint32_t(0);

    /// Identity rows (one per stored voxel) unless `m.wantedS` leaves voxels out and the
    /// result has more than one coefficient.
    ShRows(const Medium& m, int coeffs);

    /// Rows held: the wanted voxels' count, or every stored voxel's.
    size_t count() const { return count_; }
    /// Row of stored voxel v per voxel, kNone where none is held; null when the rows are
    /// the identity.
    const std::uint32_t* map() const { return row_.empty() ? nullptr : row_.data(); }
    bool compact() const { return !row_.empty(); }

    /// Turns `sh` ([row][coeff][rgb], count() rows) into one row per stored voxel, 0 where
    /// none was held.
    void expand(std::vector<float>& sh, int coeffs) const;
    /// The row map, handed over (this is left with the identity's empty map).
    std::vector<std::uint32_t> takeMap() { return std::move(row_); }

private:
    size_t voxels_ = 0, count_ = 0;
    std::vector<std::uint32_t> row_;
};

/// expand() of rows whose map `row` (one entry per stored voxel) was handed over: `sh`
/// ([row][coeff][rgb]) becomes one row per stored voxel, 0 where row[v] is ShRows::kNone.
void expandShRows(std::vector<float>& sh, const std::vector<std::uint32_t>& row, int coeffs);

}  // namespace lpm
