// Number formatting shared by the bake's messages, metadata and stats.
#pragma once

#include <iomanip>
#include <sstream>
#include <string>

#include "core/math.h"

namespace lpm {

/// Six significant digits: what messages and descriptive metadata show.
inline std::string fmt(double v) {
    std::ostringstream s;
    s << std::setprecision(6) << v;
    return s.str();
}
/// Every digit (round-trips a double): what settings comparisons use.
inline std::string fmtExact(double v) {
    std::ostringstream s;
    s << std::setprecision(17) << v;
    return s.str();
}
inline std::string fmtRgb(const RGB& c) { return fmt(c.r) + "," + fmt(c.g) + "," + fmt(c.b); }
inline std::string fmtVec(const Vec3& v) { return fmt(v.x) + "," + fmt(v.y) + "," + fmt(v.z); }

/// JSON string body: quotes and backslashes escaped, control bytes dropped to spaces.
inline std::string jsonEscape(const std::string& s) {
    std::string o;
    for (char c : s) {
        if (c == '"' || c == '\\') o += '\\', o += c;
        else if (c == '\n') o += "\\n";
        else if (static_cast<unsigned char>(c) < 0x20) o += ' ';
        else o += c;
    }
    return o;
}

}  // namespace lpm
