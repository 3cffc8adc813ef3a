// Range rules of the solver's settings, in one place.
#include "core/lpm_settings.h"

#include <cmath>

#include "core/error.h"
#include "core/sh.h"

namespace lpm {

namespace {

void requireRange(const char* what, int v, int lo, int hi) {
    if (v < lo || v > hi)
        throw Error("LPM", std::string(what) + " must be in " + std::to_string(lo) + ".." + std::to_string(hi) +
                               ", got " + std::to_string(v));
}

void requireAutoOrRange(const char* what, int v, int lo, int hi) {
    if (v != -1 && (v < lo || v > hi))
        throw Error("LPM", std::string(what) + " must be -1 (auto) or in " + std::to_string(lo) + ".." +
                               std::to_string(hi) + ", got " + std::to_string(v));
}

void requirePositive(const char* what, double v) {
    if (!(v > 0) || !std::isfinite(v))
        throw Error("LPM", std::string(what) + " must be positive and finite, got " + std::to_string(v));
}

}  // namespace

void LpmSettings::validate() const {
    requireRange("directions per face", directionsPerFace, 1, 64);
    requireRange("rays per voxel", raysPerVoxel, 1, 16);
    requireAutoOrRange("rays per voxel of the higher orders", raysHigherOrders, 1, 16);
    requireAutoOrRange("bins per face", binsPerFace, 0, 64);
    if (binsPerFace > 0 && directionsPerFace % binsPerFace != 0)
        throw Error("LPM", "bins per face (" + std::to_string(binsPerFace) + ") must divide directions per face (" +
                               std::to_string(directionsPerFace) + ")");
    requireRange("SH order", shOrder, 0, kMaxShOrder);
    requirePositive("tolerance", tolerance);
    if (maxOrders < 1) throw Error("LPM", "max orders must be at least 1, got " + std::to_string(maxOrders));
    if (krylovAfter < 0 || coarseKrylovAfter < 0)
        throw Error("LPM", "Krylov switch points must be >= 0, got " + std::to_string(krylovAfter) + " and " +
                               std::to_string(coarseKrylovAfter));
    if (krylovRestart < 1) throw Error("LPM", "GMRES restart must be >= 1, got " + std::to_string(krylovRestart));
    requireAutoOrRange("linear source", linearSource, 0, 1);
    requirePositive("linear-source threshold", linearSourceAbove);
    requirePositive("linear-source voxel cap", linearSourceVoxelCap);
    requireAutoOrRange("delta-M", deltaM, 0, 1);
    if (!(deltaMAbove >= 0 && deltaMAbove < 1))
        throw Error("LPM", "delta-M threshold on g must be in [0, 1), got " + std::to_string(deltaMAbove));
    if (!(envHotShare >= 0 && envHotShare <= 1))
        throw Error("LPM", "hot-pixel share must be in [0, 1], got " + std::to_string(envHotShare));
    requireAutoOrRange("multi-resolution", multires, 0, 1);
    if (multiresAfter < 1)
        throw Error("LPM", "full-resolution passes before the coarse grid must be >= 1, got " +
                               std::to_string(multiresAfter));
    if (multiresMinVoxels < 0)
        throw Error("LPM", "multi-resolution voxel threshold must be >= 0, got " + std::to_string(multiresMinVoxels));
    requireAutoOrRange("coarse directions per face", multiresDirections, 1, 64);
    requireRange("subdivision", subdivide, 1, 8);
}

}  // namespace lpm
