// Bake metadata and canonical settings (bake_metadata.h).
#include "baker/bake_metadata.h"

#include <sstream>

#include "baker/text_format.h"
#include "vdb_io/bake_digest.h"
#include "vdb_io/bake_file.h"
#include "vdb_io/bake_schema.h"

namespace lpm {

std::string canonicalSettings(const BakeOptions& o) {
    std::ostringstream c;
    auto line = [&](const std::string& k, const std::string& v) { c << k << '=' << v << '\n'; };
    auto num = [&](const std::string& k, double v) { line(k, fmtExact(v)); };
    auto rgb = [&](const std::string& k, const RGB& v) {
        line(k, fmtExact(v.r) + "," + fmtExact(v.g) + "," + fmtExact(v.b));
    };
    line("version", LPM_VERSION_STRING);
    line("input", o.input);
    line("grid", o.grid);
    num("grid_index", o.gridIndex);
    num("convert_level_set", o.convertLevelSet);
    num("sanitize", o.sanitize);
    num("density_scale", o.densityScale);
    rgb("albedo", o.albedo);
    num("g", o.g);
    line("emission_grid", o.emissionGrid);
    num("emission_scale", o.emissionScale);
    line("temperature_grid", o.temperatureGrid);
    num("temperature_scale", o.temperatureScale);
    num("temperature_offset", o.temperatureOffset);
    num("temperature_intensity", o.temperatureIntensity);
    line("env", o.env);
    line("env_colorspace", o.envColorSpace);
    line("working_space", o.workingSpace);
    num("env_rotate", o.envRotateDeg);
    num("env_scale", o.envScale);
    line("up_axis", upAxisName(o.upAxis));
    for (const SunOption& s : o.suns) {
        line("sun_toward", fmtExact(s.toSun.x) + "," + fmtExact(s.toSun.y) + "," + fmtExact(s.toSun.z));
        rgb("sun_irradiance", s.irradiance);
        num("sun_angle", s.angleDeg);
    }
    const LpmSettings& s = o.solver;
    num("directions_per_face", s.directionsPerFace);
    num("rays_per_voxel", s.raysPerVoxel);
    num("rays_higher_orders", s.raysHigherOrders);
    num("bins_per_face", s.binsPerFace);
    num("sh_order", s.shOrder);
    num("tolerance", s.tolerance);
    num("max_orders", s.maxOrders);
    num("krylov", s.krylov);
    num("krylov_after", s.krylovAfter);
    num("coarse_krylov_after", s.coarseKrylovAfter);
    num("krylov_restart", s.krylovRestart);
    num("source", s.linearSource);
    num("linear_source_above", s.linearSourceAbove);
    num("linear_source_diffusive", s.linearSourceDiffusive);
    num("linear_source_voxel_cap", s.linearSourceVoxelCap);
    num("delta_m", s.deltaM);
    num("delta_m_above", s.deltaMAbove);
    num("env_hot_share", s.envHotShare);
    num("multires", s.multires);
    num("multires_after", s.multiresAfter);
    num("separable_source", s.separableSource);
    num("coarse_tail_extrapolation", s.coarseTailExtrapolation);
    num("shaped_coarse_tail", s.shapedCoarseTail);
    num("shaped_tail_above", s.shapedTailAbove);
    num("diffusion_tail", s.diffusionTail);
    num("diffusion_tail_albedo", s.diffusionTailAlbedo);
    num("diffusion_tail_tau", s.diffusionTailTau);
    num("diffusion_tail_size", s.diffusionTailSize);
    num("cycle_smoothing", s.cycleSmoothing);
    num("multires_min_voxels", s.multiresMinVoxels);
    num("multires_directions", s.multiresDirections);
    num("subdivide", s.subdivide);
    num("half", o.half);
    num("no_density", o.noDensity);
    num("renderer_grids", o.rendererGrids);
    num("solve_scale", o.solveScale);
    num("sun_term", o.sunTerm);
    return c.str();
}

std::string settingsDigest(const BakeOptions& o) {
    const std::string c = canonicalSettings(o);
    return hex64(fnv1a(c.data(), c.size()));
}

namespace {

/// The --verify report (core/verify.h) and --max-error's verdict.
void putVerify(openvdb::MetaMap& meta, const BakeOptions& o, const BakeSummary& sum) {
    using namespace bakekey;
    const VerifyReport& v = sum.verify;
    putDouble(meta, verifyError, v.error);
    putDouble(meta, verifyErrorLow, v.low);
    putDouble(meta, verifyErrorHigh, v.high);
    putDouble(meta, verifyConfidence, v.confidence);
    putInt(meta, verifyProbes, v.probes);
    putInt(meta, verifyPaths, v.pathsPerProbe);
    putDouble(meta, verifyNoise, v.mcNoise);
    putDouble(meta, verifySeconds, v.seconds);
    if (o.maxError >= 0) putDouble(meta, verifyMaxError, o.maxError);
    putBool(meta, verifyFailed, sum.verifyFailed);
}

}  // namespace

openvdb::MetaMap bakeMetadata(const BakeOptions& o, const BakeSummary& sum, const LpmResult& res, const EnvInput& env,
                              std::uint64_t sanitizedCount) {
    openvdb::MetaMap meta;
    using namespace bakekey;
    auto str = [&](const MetaKey& k, const std::string& v) { putString(meta, k, v); };
    auto dbl = [&](const MetaKey& k, double v) { putDouble(meta, k, v); };
    auto i32 = [&](const MetaKey& k, int v) { putInt(meta, k, v); };
    auto rgb = [&](const MetaKey& k, const RGB& c) { putVec3(meta, k, c.r, c.g, c.b); };
    auto flag = [&](const MetaKey& k, bool v) { putBool(meta, k, v); };
    i32(formatVersion, kBakeFormatVersion);
    str(version, std::string("lpmbake ") + LPM_VERSION_STRING);
    i32(shOrder, res.shOrder);
    i32(bakekey::shCount, res.coeffs);
    str(shBasis,
        "real orthonormal spherical harmonics, ACN index k = l*l + l + m, no Condon-Shortley phase; "
        "Y0 = 0.282095, Y1 = 0.488603 y, Y2 = 0.488603 z, Y3 = 0.488603 x (solver_notes section 5); "
        "directions in world space (the grids' transform frame)");
    str(shGrids, "sh_0 .. sh_" + std::to_string(res.coeffs - 1) + ": Vec3f, RGB in xyz");
    str(shNegativeLobes,
        "coefficients are not windowed; evaluating S may give small negative values: clamp "
        "at zero when shading (lpmbake render does)");
    str(quantity,
        "S(x,w) = Int p(w,w') L(x,w') dw': phase-weighted in-scattered radiance, w = direction in "
        "which light travels; does not contain sigma_s");
    str(usage,
        "renderer adds sigma_s(x)*S(x,-view) per unit length along a camera ray with direction view, "
        "sigma_s = albedo * density * density_scale; scatter = direction-averaged S for shaders that use "
        "it as emission (multiply by sigma_s)");
    str(units,
        "S: radiance in the working colour space (environment pixels * env_scale, sun irradiance per "
        "steradian); lengths: world units of the grid transform; sigma_t = density * density_scale per "
        "world unit");
    str(frame, "world");
    str(upAxis, upAxisName(o.upAxis));
    str(workingColorspace, env.workingSpace.empty() ? o.workingSpace : env.workingSpace);
    str(densityGrid, o.noDensity ? "" : "density");
    dbl(densityScale, o.densityScale);
    rgb(albedo, o.albedo);
    dbl(g, o.g);
    str(phaseFunction, "Henyey-Greenstein");
    std::string lightsDesc;
    if (!o.env.empty()) {
        str(envFile, o.env);
        str(envColorspace, env.colorSpace);
        dbl(envRotateYDeg, o.envRotateDeg);
        dbl(envScale, o.envScale);
        str(envOrientation, o.upAxis == UpAxis::Z
                                ? "lat-long, OpenEXR ImfEnvmap convention, turned +90 deg about +X: zenith +Z, "
                                  "image centre toward -Y; env_rotate_y_deg turns it about +Z"
                                : "lat-long, OpenEXR ImfEnvmap convention, +Y up");
        lightsDesc += "environment '" + o.env + "' (" + env.colorSpace + ", rotate " + fmt(o.envRotateDeg) +
                      " deg, scale " + fmt(o.envScale) + ")";
    }
    i32(sunCount, int(o.suns.size()));
    std::string sunsDesc;
    for (size_t i = 0; i < o.suns.size(); ++i) {
        const auto& s = o.suns[i];
        sunsDesc += (i ? "; " : "") + std::string("toward ") + fmtVec(normalize(s.toSun)) + " irradiance " +
                    fmtRgb(s.irradiance) + " angle " + fmt(s.angleDeg) + " deg";
    }
    if (!o.suns.empty()) {
        str(suns, sunsDesc);
        lightsDesc += std::string(lightsDesc.empty() ? "" : "; ") + "suns: " + sunsDesc;
    }
    if (!o.temperatureGrid.empty()) {
        str(temperatureGrid, o.temperatureGrid);
        dbl(temperatureScale, o.temperatureScale);
        dbl(temperatureOffset, o.temperatureOffset);
        dbl(temperatureIntensity, o.temperatureIntensity);
        str(temperatureConvention,
            "Kelvin = value * temperature_scale + temperature_offset; L_e = "
            "temperature_intensity * black body (Planck x CIE 1931), 6500 K -> luminance 1, "
            "in the working colour space; written as grid 'emission'");
        lightsDesc += std::string(lightsDesc.empty() ? "" : "; ") + "temperature grid '" + o.temperatureGrid + "'";
    }
    if (!o.emissionGrid.empty()) {
        str(emissionGrid, o.emissionGrid);
        dbl(emissionScale, o.emissionScale);
        str(emissionConvention,
            "emitted radiance L_e = value * emission_scale; source term sigma_a * L_e "
            "(pbrt-v4); written as grid 'emission'");
        lightsDesc += std::string(lightsDesc.empty() ? "" : "; ") + "emission grid '" + o.emissionGrid + "'";
    }
    str(lights, lightsDesc);
    i32(directionsPerFace, o.solver.directionsPerFace);
    i32(raysPerVoxel, o.solver.raysPerVoxel);
    i32(raysHigherOrders, o.solver.raysHigherOrders);
    i32(binsPerFace, o.solver.binsPerFace);
    str(quality, o.quality);
    dbl(tolerance, o.solver.tolerance);
    i32(maxOrders, o.solver.maxOrders);
    i32(subdivide, o.solver.subdivide);
    str(multires, o.solver.multires < 0 ? "auto" : (o.solver.multires ? "on" : "off"));
    i32(multiresAfter, o.solver.multiresAfter);
    str(separableSources, o.solver.separableSource < 0 ? "auto" : (o.solver.separableSource ? "on" : "off"));
    str(sourceShape, o.solver.linearSource < 0 ? "auto" : (o.solver.linearSource ? "linear" : "constant"));
    str(deltaM, o.solver.deltaM < 0 ? "auto" : (o.solver.deltaM ? "on" : "off"));
    dbl(envHotShare, o.solver.envHotShare);
    dbl(solveScale, o.solveScale);
    putVec3i(meta, solveGridDims, sum.solveDims[0], sum.solveDims[1], sum.solveDims[2]);
    putVec3(meta, solveVoxelSize, sum.solveVoxelSize.x, sum.solveVoxelSize.y, sum.solveVoxelSize.z);
    flag(krylov, o.solver.krylov);
    str(solver, "Light Propagation Maps (discrete ordinates, source iteration with GMRES acceleration); " +
                    std::to_string(res.directionCount) + " directions, " + std::to_string(res.binCount) +
                    " unshot bins");
    i32(passes, sum.passes);
    dbl(residual, res.residual);
    flag(converged, res.converged);
    std::string dec;
    for (const auto& d : res.decisions) dec += (dec.empty() ? "" : "; ") + d;
    str(decisions, dec);
    str(inputFile, o.input);
    str(inputGrid, o.grid);
    i32(inputGridIndex, std::max(0, o.gridIndex));
    flag(empty, sum.empty);
    putInt64(meta, sanitizedValues, std::int64_t(sanitizedCount));
    str(storage, o.half ? "half" : "float32");
    flag(rendererGrids, o.rendererGrids);
    dbl(timeReadS, sum.secondsRead);
    dbl(timeEnvS, sum.secondsEnv);
    dbl(timeSolveS, sum.secondsSolve);
    str(timings, "read " + fmt(sum.secondsRead) + " s, environment " + fmt(sum.secondsEnv) + " s, solve " +
                     fmt(sum.secondsSolve) + " s");
    if (!o.commandLine.empty()) str(commandLine, o.commandLine);
    i32(sunTermCount, int(res.sunTerms.size()));
    if (!res.sunTerms.empty()) {
        dbl(sunTermG, o.g);
        str(sunTermConvention,
            "exact single scattering of each sun K, not in the SH grids: S(x, w) += E_K T_K(x) p_HG(g; dot(-toward_K, "
            "w)), w = direction the scattered light travels (S(x, -view) for a camera ray along view), T_K = grid "
            "sun_transmittance_K (voxel mean of the beam's transmittance), E_K = lpm:sun_term_K_irradiance, g = "
            "lpm:sun_term_g, p_HG = (1 - g^2) / (4 pi (1 + g^2 - 2 g cos)^1.5); the scatter grid includes it");
    }
    for (size_t k = 0; k < res.sunTerms.size(); ++k) {
        const SunTerm& t = res.sunTerms[k];
        putVec3(meta, sunTermKey(int(k), SunTermField::Toward), t.toSun.x, t.toSun.y, t.toSun.z);
        rgb(sunTermKey(int(k), SunTermField::Irradiance), t.irradiance);
        dbl(sunTermKey(int(k), SunTermField::AngleDeg), t.angularDiameterDeg);
        str(sunTermKey(int(k), SunTermField::Source), t.fromEnvironment ? "environment hot pixel" : "--sun");
        str(sunTermKey(int(k), SunTermField::Grid), sunTransmittanceGridName(int(k)));
    }
    if (sum.verified) putVerify(meta, o, sum);
    str(settings, canonicalSettings(o));
    str(bakekey::settingsDigest, lpm::settingsDigest(o));
    return meta;
}

}  // namespace lpm
