// Bake statistics as JSON (stats_json.h).
#include "baker/stats_json.h"

#include <algorithm>

#include "core/parallel.h"
#include "vdb_io/atomic_file.h"

namespace lpm {

namespace {

using nlohmann::json;

json planJson(const SolvePlan& p) {
    json decisions = json::array();
    for (const PlanDecision& d : p.decisions) {
        json e = {{"decision", d.what}, {"reason", d.why}};
        if (d.predictedSeconds >= 0) e["predicted_s"] = d.predictedSeconds;
        if (d.predictedBytes >= 0) e["predicted_mib"] = d.predictedBytes / (1 << 20);
        decisions.push_back(e);
    }
    return {{"predicted_fine_pass_segments", p.predictedSegmentsPerFinePass},
            {"predicted_fine_pass_s", p.predictedSecondsPerFinePass},
            {"predicted_buffers_mib", p.predictedBytes / (1 << 20)},
            {"decisions", decisions}};
}

/// The measured cost of each stage of the solve (docs/solve_plan.md).
json stagesJson(const LpmResult& r) {
    double single = 0, fine = 0, coarse = 0, krylov = 0, firstFine = -1;
    std::uint64_t firstFineSegments = 0;
    for (const PassStats& ps : r.passes) {
        if (ps.pass == 0) single += ps.seconds;
        else if (ps.coarse) coarse += ps.seconds;
        else if (ps.krylov) krylov += ps.seconds;
        else fine += ps.seconds;
        if (ps.pass > 0 && !ps.coarse && firstFine < 0) {
            firstFine = ps.seconds;
            firstFineSegments = ps.segments;
        }
    }
    return {{"single_scattering", single},
            {"sun_terms", r.sunTermSeconds},
            {"fine_orders", fine},
            {"coarse_orders", coarse},
            {"gmres", krylov},
            {"first_fine_pass", std::max(0.0, firstFine)},
            {"first_fine_pass_segments", firstFineSegments}};
}

json passesJson(const LpmResult* r) {
    json passes = json::array();
    if (!r) return passes;
    for (const PassStats& p : r->passes)
        passes.push_back({{"pass", p.pass},
                          {"injected", p.injected},
                          {"scattered", p.scattered},
                          {"absorbed", p.absorbed},
                          {"escaped", p.escaped},
                          {"seconds", p.seconds},
                          {"krylov", p.krylov},
                          {"coarse", p.coarse},
                          {"segments", p.segments}});
    return passes;
}

}  // namespace

json statsJson(const BakeOptions& o, const BakeSummary& s, const LpmResult* r) {
    json j = {
        {"tool", std::string("lpmbake ") + LPM_VERSION_STRING},
        {"input", o.input},
        {"grid", o.grid},
        {"output", o.output},
        {"threads", maxThreads()},
        {"empty", s.empty},
        {"voxels", {{"active", s.activeVoxels}, {"stored", s.denseVoxels}, {"bounding_box", s.boxVoxels}}},
        {"tiles", {{"size", Medium::kTile}, {"stored", s.tilesStored}, {"in_box", s.tilesInBox}}},
        {"solve_grid",
         {{"solve_scale", s.solveScale},
          {"dims", {s.solveDims[0], s.solveDims[1], s.solveDims[2]}},
          {"voxel_size", {s.solveVoxelSize.x, s.solveVoxelSize.y, s.solveVoxelSize.z}}}},
        {"timings_s",
         {{"read", s.secondsRead},
          {"environment", s.secondsEnv},
          {"solve", s.secondsSolve},
          {"write", s.secondsWrite},
          {"total", s.secondsTotal}}},
        {"environment_source", s.envSource},
        {"sh_order", s.shOrder},
        {"passes", s.passes},
        {"residual", s.residual},
        {"converged", s.converged},
        {"ray_segments", s.segments},
        {"ray_segments_per_second", s.secondsSolve > 0 ? double(s.segments) / s.secondsSolve : 0.0},
        {"peak_rss_mib", double(s.peakRssKiB) / 1024.0},
        {"pass_stats", passesJson(r)},
        {"decisions", r ? json(r->decisions) : json::array()},
    };
    if (s.verified)
        j["verify"] = {{"error", s.verify.error},
                       {"low", s.verify.low},
                       {"high", s.verify.high},
                       {"confidence", s.verify.confidence},
                       {"probes", s.verify.probes},
                       {"paths_per_probe", s.verify.pathsPerProbe},
                       {"mc_noise", s.verify.mcNoise},
                       {"seconds", s.verify.seconds},
                       {"max_error", o.maxError >= 0 ? json(o.maxError) : json(nullptr)},
                       {"failed", s.verifyFailed}};
    if (r) {
        j["plan"] = planJson(r->plan);
        j["stages_s"] = stagesJson(*r);
    }
    return j;
}

void writeStats(const BakeOptions& o, const BakeSummary& s, const LpmResult* r) {
    writeTextFileAtomically("stats", o.statsPath, statsJson(o, s, r).dump(2) + "\n", {o.input, o.env, o.output});
}

}  // namespace lpm
