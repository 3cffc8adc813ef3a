// The fine grid's SH result while a two-grid cycle's coarse grid solves (docs/multires.md,
// "The SH result during the coarse solve"). Nothing reads or adds to it then, yet at SH
// order 2 it is the largest buffer the coarse phase holds (108 B per written voxel). It
// waits with band 0 in float and the directional bands in half precision (core/half_buffer.h,
// one scale for the whole result): 12 + 48 B per row at order 2 instead of 108. Each
// directional coefficient is rounded once per cycle, to within 2^-11 of its value
// (wherever it is at least 2^-28 of the result's largest; below, to within 2^-39 of the
// largest); band 0 comes back exactly.
#pragma once

#include <vector>

#include "core/half_buffer.h"

namespace lpm {

class HeldSh {
public:
    /// Takes sh's values ([row][coeff][rgb], `coeffs` per row, at least 2) and gives its
    /// pages back (discardPages, core/malloc_policy.h): its storage stays allocated, so the
    /// values return to the same addresses, and the heap need not grow for them beside the
    /// coarse solve's freed buffers (a new block did: +118 MiB in one run of the cumulus).
    HeldSh(std::vector<float>& sh, int coeffs);
    /// Writes the held values back into sh (the vector given to the constructor, its size
    /// unchanged): band 0 as it was, the other bands as rounded. Frees the held copy.
    void restore(std::vector<float>& sh);
    size_t rows() const { return band0_.size() / 3; }

private:
    int coeffs_;
    std::vector<float> band0_;  ///< [row][rgb]
    HalfBuffer directional_;    ///< [row][coeff 1..][rgb]
};

}  // namespace lpm
