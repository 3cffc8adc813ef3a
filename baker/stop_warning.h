// The warning of a bake whose solve stopped before its tolerance: which measure stopped
// short and which cap stopped it, since that decides what helps.
#pragma once

#include <string>

#include "core/lpm_solver.h"

namespace lpm {

/// Empty when the solve converged; else one line (without the "warning: " prefix) naming
/// the residual against --tolerance (or, where the signed residual met it, the absolute
/// residual against its line: a residual that changes sign between voxels) and what
/// would help: more orders, or, where the two-grid solve ran its cycles out, full
/// resolution.
std::string stopWarning(const LpmResult& res, double tolerance);

}  // namespace lpm
