// Range rules of the solver's settings, in one place.
#include "core/lpm_settings.h"

#include <cmath>
#include <sstream>

#include "core/error.h"
#include "core/sh.h"

namespace lpm {

namespace {

std::string text(double v) {
    std::ostringstream o;
    o << v;
    return o.str();
}

void requireRange(const char* field, int v, int lo, int hi) {
    if (v < lo || v > hi)
        throw SettingError(
            "LPM", field,
            "must be in " + std::to_string(lo) + ".." + std::to_string(hi) + ", got " + std::to_string(v));
}

void requireAutoOrRange(const char* field, int v, int lo, int hi) {
    if (v != -1 && (v < lo || v > hi))
        throw SettingError(
            "LPM", field,
            "must be -1 (auto) or in " + std::to_string(lo) + ".." + std::to_string(hi) + ", got " + std::to_string(v));
}

void requireAtLeast(const char* field, int v, int lo) {
    if (v < lo) throw SettingError("LPM", field, "must be >= " + std::to_string(lo) + ", got " + std::to_string(v));
}

void requirePositive(const char* field, double v) {
    if (!(v > 0) || !std::isfinite(v)) throw SettingError("LPM", field, "must be positive and finite, got " + text(v));
}

/// lo <= v < hi (closedTop: v <= hi).
void requireInterval(const char* field, double v, double lo, double hi, bool closedTop) {
    if (!(v >= lo && (closedTop ? v <= hi : v < hi)))
        throw SettingError("LPM", field,
                           "must be in [" + text(lo) + ", " + text(hi) + (closedTop ? "]" : ")") + ", got " + text(v));
}

}  // namespace

void LpmSettings::validate() const {
    requireRange("directionsPerFace", directionsPerFace, 1, kMaxDirectionsPerFace);
    requireRange("raysPerVoxel", raysPerVoxel, 1, kMaxRaysPerVoxel);
    requireAutoOrRange("raysHigherOrders", raysHigherOrders, 1, kMaxRaysPerVoxel);
    requireAutoOrRange("binsPerFace", binsPerFace, 0, kMaxDirectionsPerFace);
    if (binsPerFace > 0 && directionsPerFace % binsPerFace != 0)
        throw SettingError(
            "LPM", "binsPerFace",
            std::to_string(binsPerFace) + " must divide directions per face " + std::to_string(directionsPerFace));
    requireRange("shOrder", shOrder, 0, kMaxShOrder);
    requirePositive("tolerance", tolerance);
    requireAtLeast("maxOrders", maxOrders, 1);
    requireAtLeast("krylovAfter", krylovAfter, 0);
    requireAtLeast("coarseKrylovAfter", coarseKrylovAfter, 0);
    requireAtLeast("krylovRestart", krylovRestart, 1);
    requirePositive("krylovBytes", krylovBytes);
    requireAutoOrRange("linearSource", linearSource, 0, 1);
    requirePositive("linearSourceAbove", linearSourceAbove);
    requirePositive("linearSourceDiffusive", linearSourceDiffusive);
    requirePositive("linearSourceVoxelCap", linearSourceVoxelCap);
    requireAutoOrRange("deltaM", deltaM, 0, 1);
    requireInterval("deltaMAbove", deltaMAbove, 0, 1, false);
    requireInterval("envHotShare", envHotShare, 0, 1, true);
    requireAutoOrRange("multires", multires, 0, 1);
    requireAtLeast("multiresAfter", multiresAfter, 1);
    if (multiresMinVoxels < 0)
        throw SettingError("LPM", "multiresMinVoxels", "must be >= 0, got " + std::to_string(multiresMinVoxels));
    requireAutoOrRange("multiresDirections", multiresDirections, 1, kMaxDirectionsPerFace);
    requireAutoOrRange("separableSource", separableSource, 0, 1);
    requireAutoOrRange("shapedCoarseTail", shapedCoarseTail, 0, 1);
    if (!(shapedTailAbove >= 0))
        throw SettingError("LPM", "shapedTailAbove", "must be >= 0, got " + std::to_string(shapedTailAbove));
    requireAutoOrRange("diffusionTail", diffusionTail, 0, 1);
    if (!(diffusionTailAlbedo >= 0) || !(diffusionTailTau >= 0) || !(diffusionTailSize >= 0))
        throw SettingError("LPM", "diffusionTailAlbedo/diffusionTailTau/diffusionTailSize",
                           "must be >= 0, got " + std::to_string(diffusionTailAlbedo) + ", " +
                               std::to_string(diffusionTailTau) + " and " + std::to_string(diffusionTailSize));
    requireRange("cycleSmoothing", cycleSmoothing, 0, 4);
    if (!(extrapolationTolerance >= 0) || !std::isfinite(extrapolationTolerance))
        throw SettingError("LPM", "extrapolationTolerance",
                           "must be finite and >= 0, got " + std::to_string(extrapolationTolerance));
    requireRange("subdivide", subdivide, 1, kMaxSubdivide);
}

}  // namespace lpm
