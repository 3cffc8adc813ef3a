// Peak resident memory of this process, resettable between the frames of a sequence.
#pragma once

#include <sys/resource.h>

#include <fstream>
#include <string>

namespace lpm {

/// Peak resident set size since the process started or since resetPeakRss() (Linux
/// VmHWM), KiB; getrusage's lifetime peak where /proc is not readable.
inline long peakRssKiB() {
    std::ifstream f("/proc/self/status");
    std::string key;
    while (f >> key) {
        if (key == "VmHWM:") {
            long kib = 0;
            f >> kib;
            return kib;
        }
        f.ignore(1 << 12, '\n');
    }
    struct rusage u {};
    getrusage(RUSAGE_SELF, &u);
    return u.ru_maxrss;
}

/// Starts a new peak (Linux >= 4.0: clear_refs "5"); ignored where not allowed.
inline void resetPeakRss() { std::ofstream("/proc/self/clear_refs") << "5"; }

}  // namespace lpm
