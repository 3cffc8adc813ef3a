// The quality presets (quality.h). Their measured error and time: docs/accuracy.md.
#include "baker/quality.h"

#include <algorithm>

#include "core/error.h"

namespace lpm {

const std::vector<QualityPreset>& qualityPresets() {
    // The measured figures: docs/accuracy.md, "Presets" (six scenes, against Monte Carlo).
    static const std::vector<QualityPreset> presets = {
        {"preview", 2, 1, 1e-2, -1, "n = 2, r = 1, tolerance 1e-2: 2-6% image error, 1.4-2.9x faster than default"},
        {"default", 4, 2, 1e-3, -1,
         "n = 4, r = 2, tolerance 1e-3 (the defaults): 0.4-2.3% band-0 error on thin and moderate media"},
        {"production", 6, 2, 1e-4, -1,
         "n = 6, r = 2, tolerance 1e-4: 0.1-1.2% on thin media, 2.2-3.7x the default's time"},
    };
    return presets;
}

const std::vector<std::string>& qualityFlags() {
    static const std::vector<std::string> flags = {"--directions-per-face", "--rays-per-voxel", "--tolerance",
                                                   "--multires"};
    return flags;
}

void applyQuality(const std::string& name, LpmSettings& s, const std::vector<std::string>& explicitFlags) {
    const auto& all = qualityPresets();
    const auto it = std::find_if(all.begin(), all.end(), [&](const QualityPreset& p) { return p.name == name; });
    if (it == all.end())
        throw SettingError("quality", "quality", "must be preview, default or production, got '" + name + "'");
    const auto given = [&](const char* flag) {
        return std::find(explicitFlags.begin(), explicitFlags.end(), flag) != explicitFlags.end();
    };
    if (!given("--directions-per-face")) s.directionsPerFace = it->directionsPerFace;
    if (!given("--rays-per-voxel")) s.raysPerVoxel = it->raysPerVoxel;
    if (!given("--tolerance")) s.tolerance = it->tolerance;
    if (!given("--multires")) s.multires = it->multires;
}

}  // namespace lpm
