// Colour management through OpenColorIO. lpmbake ships data/config.ocio (OCIO 2.1 has no
// built-in configs): ACES2065-1 reference, ACEScg, lin_rec709 (aliases Linear/linear),
// sRGB (encoded), raw, and an sRGB display with a "Standard" view. $OCIO wins when set.
#pragma once

#include <string>
#include <vector>

namespace lpm {

/// Path of the config in use: $OCIO if set, else the shipped config.ocio (next to the
/// executable's share/lpmbake, or the source tree's data/). Throws InputError if none.
std::string ocioConfigPath();

/// True if the config knows `name` (colour space, alias or role).
bool colorSpaceKnown(const std::string& name);

/// Canonical colour space name for `name` (resolves roles and aliases); throws InputError
/// listing the known colour spaces when the config does not know it.
std::string canonicalColorSpace(const std::string& name);

/// Converts packed RGB floats (3 per pixel) in place from `src` to `dst`.
void convertColor(std::vector<float>& rgb, const std::string& src, const std::string& dst);

/// Converts packed RGB floats from scene-linear `src` to display-encoded values of the
/// config's display `display` / view `view` (defaults: first display, its first view).
void convertToDisplay(std::vector<float>& rgb, const std::string& src, const std::string& display = "",
                      const std::string& view = "");

/// Names of the colour spaces in the config, for messages.
std::vector<std::string> colorSpaceNames();

}  // namespace lpm
