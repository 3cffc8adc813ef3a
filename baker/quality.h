// --quality preview|default|production: named sets of solver knobs, chosen from the
// measured error-versus-time study (docs/accuracy.md, "Presets"; scripts/accuracy/run.sh).
// A knob given explicitly on the command line overrides the preset's value.
#pragma once

#include <string>
#include <vector>

#include "core/lpm_settings.h"

namespace lpm {

struct QualityPreset {
    std::string name;
    int directionsPerFace;
    int raysPerVoxel;
    double tolerance;
    int multires;         ///< -1 auto, 0 off
    std::string purpose;  ///< one line for --help
};

/// preview, default, production (in that order).
const std::vector<QualityPreset>& qualityPresets();

/// The knobs each preset sets, as flags: --directions-per-face, --rays-per-voxel,
/// --tolerance, --multires.
const std::vector<std::string>& qualityFlags();

/// Sets preset `name`'s knobs in `s`, except those whose flag is in `explicitFlags`.
/// Throws SettingError (field "quality") for an unknown name.
void applyQuality(const std::string& name, LpmSettings& s, const std::vector<std::string>& explicitFlags);

}  // namespace lpm
