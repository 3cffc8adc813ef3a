// The bake's statistics as JSON (--stats FILE, docs/cli.md "Statistics"): sizes, timings,
// passes, the effect plan with its predicted costs and the measured cost of each stage.
#pragma once

#include <nlohmann/json.hpp>

#include "baker/options.h"

namespace lpm {

/// The statistics of one bake; `result` is null for an empty input (no solve).
nlohmann::json statsJson(const BakeOptions& o, const BakeSummary& s, const LpmResult* result);

/// Writes statsJson() atomically to o.statsPath. Throws OutputError.
void writeStats(const BakeOptions& o, const BakeSummary& s, const LpmResult* result);

}  // namespace lpm
