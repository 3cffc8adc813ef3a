// Error kinds for the file adapters. Both are lpm::Error ("component: message"), so
// callers that do not care catch lpm::Error; the CLI maps them to distinct exit codes
// (input problems: 2, output problems: 3).
#pragma once

#include "core/error.h"

namespace lpm {

/// A problem with something the user gave us: a file, a grid, an image, a value in it.
class InputError : public Error {
public:
    using Error::Error;
};

/// A problem producing the result: unwritable directory, disk full, clobbering the input.
class OutputError : public Error {
public:
    using Error::Error;
};

}  // namespace lpm
