// Frame patterns in paths and frame lists (frame_pattern.h).
#include "baker/frame_pattern.h"

#include <algorithm>
#include <cctype>
#include <cstdlib>
#include <set>
#include <string>

#include "baker/options.h"

namespace lpm {

namespace {

/// One frame pattern found at `pos`: its length in the path and the zero-padding width
/// (0 = as many digits as needed). length 0: no pattern starts at `pos`.
struct PatternAt {
    size_t length = 0;
    int pad = 0;
};

PatternAt patternAt(const std::string& s, size_t pos) {
    PatternAt p;
    const char c = s[pos];
    if (c == '#' || c == '@') {
        size_t e = pos;
        while (e < s.size() && s[e] == c) ++e;
        p.length = e - pos;
        p.pad = int(p.length);
    } else if (c == '%') {
        // %d or %0Nd
        size_t e = pos + 1;
        std::string width;
        if (e < s.size() && s[e] == '0') {
            ++e;
            while (e < s.size() && std::isdigit(static_cast<unsigned char>(s[e]))) width += s[e++];
            if (width.empty()) return p;
        }
        if (e < s.size() && s[e] == 'd') {
            p.length = e + 1 - pos;
            p.pad = width.empty() ? 0 : std::atoi(width.c_str());
        }
    } else if (c == '$' && pos + 1 < s.size() && s[pos + 1] == 'F') {
        // $F, $F4; not $FF (Houdini's float frame) or any longer variable name.
        size_t e = pos + 2;
        std::string width;
        while (e < s.size() && std::isdigit(static_cast<unsigned char>(s[e]))) width += s[e++];
        if (e < s.size() && (std::isalpha(static_cast<unsigned char>(s[e])) || s[e] == '_')) return p;
        p.length = e - pos;
        p.pad = width.empty() ? 0 : std::atoi(width.c_str());
    }
    if (p.pad > 16) p.length = 0;  // not a frame number anyone writes
    return p;
}

std::string padded(int frame, int pad) {
    std::string digits = std::to_string(frame < 0 ? -static_cast<long long>(frame) : static_cast<long long>(frame));
    if (int(digits.size()) < pad) digits.insert(0, size_t(pad) - digits.size(), '0');
    return (frame < 0 ? "-" : "") + digits;
}

/// Parses an integer (optionally negative) at s[pos...]; advances pos. False if none.
bool readInt(const std::string& s, size_t& pos, long long& v) {
    size_t e = pos;
    if (e < s.size() && s[e] == '-') ++e;
    const size_t digits = e;
    while (e < s.size() && std::isdigit(static_cast<unsigned char>(s[e]))) ++e;
    if (e == digits || e - digits > 10) return false;
    v = std::atoll(s.substr(pos, e - pos).c_str());
    pos = e;
    return true;
}

}  // namespace

bool hasFramePattern(const std::string& path) {
    for (size_t i = 0; i < path.size(); ++i)
        if (patternAt(path, i).length > 0) return true;
    return false;
}

std::string expandFramePattern(const std::string& path, int frame) {
    std::string out;
    for (size_t i = 0; i < path.size();) {
        const PatternAt p = patternAt(path, i);
        if (p.length == 0) {
            out += path[i++];
            continue;
        }
        out += padded(frame, p.pad);
        i += p.length;
    }
    return out;
}

std::vector<int> parseFrameList(const std::string& list) {
    constexpr long long kMaxFrames = 1000000, kLimit = 2000000000;
    auto bad = [&](const std::string& why) {
        return UsageError("frame list '" + list + "': " + why + " (expected e.g. 1001-1100, 1-50x2 or 1,5,9-12)");
    };
    std::vector<int> frames;
    std::set<int> seen;
    size_t pos = 0;
    if (list.empty()) throw bad("empty");
    while (true) {
        long long a = 0, b = 0, step = 1;
        if (!readInt(list, pos, a)) throw bad("a frame number is missing or too long");
        b = a;
        if (pos < list.size() && list[pos] == '-') {
            ++pos;
            if (!readInt(list, pos, b)) throw bad("a range has no end");
            if (b < a) throw bad("range " + std::to_string(a) + "-" + std::to_string(b) + " runs backwards");
            if (pos < list.size() && list[pos] == 'x') {
                ++pos;
                if (!readInt(list, pos, step) || step < 1) throw bad("a step must be a whole number >= 1");
            }
        }
        if (a < -kLimit || b > kLimit) throw bad("frame numbers must lie within +-2e9");
        if ((b - a) / step + 1 + static_cast<long long>(frames.size()) > kMaxFrames) throw bad("more than 1e6 frames");
        for (long long f = a; f <= b; f += step)
            if (seen.insert(int(f)).second) frames.push_back(int(f));
        if (pos == list.size()) break;
        if (list[pos] != ',') throw bad("unexpected '" + std::string(1, list[pos]) + "'");
        ++pos;
    }
    return frames;
}

std::string formatFrameList(std::vector<int> frames) {
    std::sort(frames.begin(), frames.end());
    frames.erase(std::unique(frames.begin(), frames.end()), frames.end());
    std::string out;
    for (size_t i = 0; i < frames.size();) {
        size_t j = i;
        while (j + 1 < frames.size() && frames[j + 1] == frames[j] + 1) ++j;
        if (!out.empty()) out += ',';
        out += std::to_string(frames[i]);
        if (j > i) out += "-" + std::to_string(frames[j]);
        i = j + 1;
    }
    return out;
}

}  // namespace lpm
