// Test helpers: the kernel's view of this process's memory (/proc/self/smaps) and the
// transparent-huge-page mode.
#pragma once

#include <cstdint>
#include <fstream>
#include <sstream>
#include <string>

namespace lpm {

/// The "THPeligible" flag of the mapping that holds p (1 or 0), or -1 when not found.
inline int thpEligible(const void* p) {
    std::ifstream smaps("/proc/self/smaps");
    std::string line;
    bool inside = false;
    const auto addr = reinterpret_cast<std::uintptr_t>(p);
    while (std::getline(smaps, line)) {
        std::uintptr_t lo = 0, hi = 0;
        char dash = 0;
        std::istringstream head(line);
        if (line.find('-') != std::string::npos && (head >> std::hex >> lo >> dash >> hi) && dash == '-')
            inside = addr >= lo && addr < hi;
        else if (inside && line.rfind("THPeligible:", 0) == 0) return std::stoi(line.substr(12));
    }
    return -1;
}

/// The kernel's THP modes line (e.g. "always [madvise] never"); empty when unknown.
inline std::string thpModes() {
    std::ifstream mode("/sys/kernel/mm/transparent_hugepage/enabled");
    std::string modes;
    std::getline(mode, modes);
    return modes;
}

/// Whether advised memory can get huge pages here.
inline bool thpUsable(const std::string& modes) { return !modes.empty() && modes.find("[never]") == std::string::npos; }

}  // namespace lpm
