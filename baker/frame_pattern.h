// Frame numbers in paths and frame lists on the command line, in the conventions TDs
// type (docs/farm.md):
//   paths:  smoke.####.vdb (4 digits, zero-padded), smoke.@@@.vdb (one digit per @),
//           smoke.%04d.vdb (printf), smoke.$F4.vdb (Houdini; $F alone is unpadded)
//   frames: 1001-1100, 1-50x2 (every second frame), 1,5,9-12, and negative frames -5--1
#pragma once

#include <string>
#include <vector>

namespace lpm {

/// True when `path` holds a frame pattern (one of the four above).
bool hasFramePattern(const std::string& path);

/// `path` with every frame pattern replaced by `frame` (padded as the pattern says; a
/// negative frame keeps its sign before the padded digits, as Houdini writes it).
/// A path without a pattern is returned unchanged.
std::string expandFramePattern(const std::string& path, int frame);

/// Frames of a frame list, in the order given, each once. Throws UsageError naming the
/// list on bad syntax, an empty or reversed range, a step below 1, or more than 1e6 frames.
std::vector<int> parseFrameList(const std::string& list);

/// The shortest comma list of numbers and ranges (a-b) for `frames` sorted ascending
/// ("" for none): the inverse of parseFrameList for sorted input.
std::string formatFrameList(std::vector<int> frames);

}  // namespace lpm
