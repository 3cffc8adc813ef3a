// Bake metadata and canonical settings (bake_metadata.h).
#include "baker/bake_metadata.h"

#include <sstream>

#include "baker/text_format.h"
#include "vdb_io/bake_digest.h"
#include "vdb_io/bake_file.h"

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
    num("linear_source_voxel_cap", s.linearSourceVoxelCap);
    num("delta_m", s.deltaM);
    num("delta_m_above", s.deltaMAbove);
    num("env_hot_share", s.envHotShare);
    num("multires", s.multires);
    num("multires_after", s.multiresAfter);
    num("multires_min_voxels", s.multiresMinVoxels);
    num("multires_directions", s.multiresDirections);
    num("subdivide", s.subdivide);
    num("half", o.half);
    num("no_density", o.noDensity);
    num("solve_scale", o.solveScale);
    num("sun_term", o.sunTerm);
    return c.str();
}

std::string settingsDigest(const BakeOptions& o) {
    const std::string c = canonicalSettings(o);
    return hex64(fnv1a(c.data(), c.size()));
}

openvdb::MetaMap bakeMetadata(const BakeOptions& o, const BakeSummary& sum, const LpmResult& res, const EnvInput& env,
                              std::uint64_t sanitizedValues) {
    openvdb::MetaMap meta;
    auto str = [&](const std::string& k, const std::string& v) { meta.insertMeta("lpm:" + k, openvdb::StringMetadata(v)); };
    auto dbl = [&](const std::string& k, double v) { meta.insertMeta("lpm:" + k, openvdb::DoubleMetadata(v)); };
    auto i32 = [&](const std::string& k, int v) { meta.insertMeta("lpm:" + k, openvdb::Int32Metadata(v)); };
    auto rgb = [&](const std::string& k, const RGB& c) {
        meta.insertMeta("lpm:" + k, openvdb::Vec3DMetadata(openvdb::Vec3d(c.r, c.g, c.b)));
    };
    i32("format_version", kBakeFormatVersion);
    str("version", std::string("lpmbake ") + LPM_VERSION_STRING);
    i32("sh_order", res.shOrder);
    i32("sh_count", res.coeffs);
    str("sh_basis", "real orthonormal spherical harmonics, ACN index k = l*l + l + m, no Condon-Shortley phase; "
                    "Y0 = 0.282095, Y1 = 0.488603 y, Y2 = 0.488603 z, Y3 = 0.488603 x (solver_notes section 5); "
                    "directions in world space (the grids' transform frame)");
    str("sh_grids", "sh_0 .. sh_" + std::to_string(res.coeffs - 1) + ": Vec3f, RGB in xyz");
    str("sh_negative_lobes", "coefficients are not windowed; evaluating S may give small negative values: clamp "
                             "at zero when shading (lpmbake render does)");
    str("quantity", "S(x,w) = Int p(w,w') L(x,w') dw': phase-weighted in-scattered radiance, w = direction in "
                    "which light travels; does not contain sigma_s");
    str("usage", "renderer adds sigma_s(x)*S(x,-view) per unit length along a camera ray with direction view, "
                 "sigma_s = albedo * density * density_scale; scatter = direction-averaged S for shaders that use "
                 "it as emission (multiply by sigma_s)");
    str("units", "S: radiance in the working colour space (environment pixels * env_scale, sun irradiance per "
                 "steradian); lengths: world units of the grid transform; sigma_t = density * density_scale per "
                 "world unit");
    str("frame", "world");
    str("up_axis", upAxisName(o.upAxis));
    str("working_colorspace", env.workingSpace.empty() ? o.workingSpace : env.workingSpace);
    str("density_grid", o.noDensity ? "" : "density");
    dbl("density_scale", o.densityScale);
    rgb("albedo", o.albedo);
    dbl("g", o.g);
    str("phase_function", "Henyey-Greenstein");
    std::string lightsDesc;
    if (!o.env.empty()) {
        str("env_file", o.env);
        str("env_colorspace", env.colorSpace);
        dbl("env_rotate_y_deg", o.envRotateDeg);
        dbl("env_scale", o.envScale);
        str("env_orientation", o.upAxis == UpAxis::Z
                                   ? "lat-long, OpenEXR ImfEnvmap convention, turned +90 deg about +X: zenith +Z, "
                                     "image centre toward -Y; env_rotate_y_deg turns it about +Z"
                                   : "lat-long, OpenEXR ImfEnvmap convention, +Y up");
        lightsDesc += "environment '" + o.env + "' (" + env.colorSpace + ", rotate " + fmt(o.envRotateDeg) +
                      " deg, scale " + fmt(o.envScale) + ")";
    }
    i32("sun_count", int(o.suns.size()));
    std::string sunsDesc;
    for (size_t i = 0; i < o.suns.size(); ++i) {
        const auto& s = o.suns[i];
        sunsDesc += (i ? "; " : "") + std::string("toward ") + fmtVec(normalize(s.toSun)) + " irradiance " +
                    fmtRgb(s.irradiance) + " angle " + fmt(s.angleDeg) + " deg";
    }
    if (!o.suns.empty()) {
        str("suns", sunsDesc);
        lightsDesc += std::string(lightsDesc.empty() ? "" : "; ") + "suns: " + sunsDesc;
    }
    if (!o.temperatureGrid.empty()) {
        str("temperature_grid", o.temperatureGrid);
        dbl("temperature_scale", o.temperatureScale);
        dbl("temperature_offset", o.temperatureOffset);
        dbl("temperature_intensity", o.temperatureIntensity);
        str("temperature_convention", "Kelvin = value * temperature_scale + temperature_offset; L_e = "
                                      "temperature_intensity * black body (Planck x CIE 1931), 6500 K -> luminance 1, "
                                      "in the working colour space; written as grid 'emission'");
        lightsDesc += std::string(lightsDesc.empty() ? "" : "; ") + "temperature grid '" + o.temperatureGrid + "'";
    }
    if (!o.emissionGrid.empty()) {
        str("emission_grid", o.emissionGrid);
        dbl("emission_scale", o.emissionScale);
        str("emission_convention", "emitted radiance L_e = value * emission_scale; source term sigma_a * L_e "
                                   "(pbrt-v4); written as grid 'emission'");
        lightsDesc += std::string(lightsDesc.empty() ? "" : "; ") + "emission grid '" + o.emissionGrid + "'";
    }
    str("lights", lightsDesc);
    i32("directions_per_face", o.solver.directionsPerFace);
    i32("rays_per_voxel", o.solver.raysPerVoxel);
    i32("rays_higher_orders", o.solver.raysHigherOrders);
    i32("bins_per_face", o.solver.binsPerFace);
    dbl("tolerance", o.solver.tolerance);
    i32("max_orders", o.solver.maxOrders);
    i32("subdivide", o.solver.subdivide);
    str("multires", o.solver.multires < 0 ? "auto" : (o.solver.multires ? "on" : "off"));
    i32("multires_after", o.solver.multiresAfter);
    str("source_shape", o.solver.linearSource < 0 ? "auto" : (o.solver.linearSource ? "linear" : "constant"));
    str("delta_m", o.solver.deltaM < 0 ? "auto" : (o.solver.deltaM ? "on" : "off"));
    dbl("env_hot_share", o.solver.envHotShare);
    dbl("solve_scale", o.solveScale);
    meta.insertMeta("lpm:solve_grid_dims",
                    openvdb::Vec3IMetadata(openvdb::Vec3i(sum.solveDims[0], sum.solveDims[1], sum.solveDims[2])));
    meta.insertMeta("lpm:solve_voxel_size", openvdb::Vec3DMetadata(openvdb::Vec3d(
                                                 sum.solveVoxelSize.x, sum.solveVoxelSize.y, sum.solveVoxelSize.z)));
    meta.insertMeta("lpm:krylov", openvdb::BoolMetadata(o.solver.krylov));
    str("solver", "Light Propagation Maps (discrete ordinates, source iteration with GMRES acceleration); " +
                      std::to_string(res.directionCount) + " directions, " + std::to_string(res.binCount) +
                      " unshot bins");
    i32("passes", sum.passes);
    dbl("residual", res.residual);
    meta.insertMeta("lpm:converged", openvdb::BoolMetadata(res.converged));
    std::string dec;
    for (const auto& d : res.decisions) dec += (dec.empty() ? "" : "; ") + d;
    str("decisions", dec);
    str("input_file", o.input);
    str("input_grid", o.grid);
    i32("input_grid_index", std::max(0, o.gridIndex));
    meta.insertMeta("lpm:empty", openvdb::BoolMetadata(sum.empty));
    meta.insertMeta("lpm:sanitized_values", openvdb::Int64Metadata(openvdb::Int64(sanitizedValues)));
    str("storage", o.half ? "half" : "float32");
    dbl("time_read_s", sum.secondsRead);
    dbl("time_env_s", sum.secondsEnv);
    dbl("time_solve_s", sum.secondsSolve);
    str("timings", "read " + fmt(sum.secondsRead) + " s, environment " + fmt(sum.secondsEnv) + " s, solve " +
                       fmt(sum.secondsSolve) + " s");
    if (!o.commandLine.empty()) str("command_line", o.commandLine);
    i32("sun_term_count", int(res.sunTerms.size()));
    if (!res.sunTerms.empty()) {
        dbl("sun_term_g", o.g);
        str("sun_term_convention",
            "exact single scattering of each sun K, not in the SH grids: S(x, w) += E_K T_K(x) p_HG(g; dot(-toward_K, "
            "w)), w = direction the scattered light travels (S(x, -view) for a camera ray along view), T_K = grid "
            "sun_transmittance_K (voxel mean of the beam's transmittance), E_K = lpm:sun_term_K_irradiance, g = "
            "lpm:sun_term_g, p_HG = (1 - g^2) / (4 pi (1 + g^2 - 2 g cos)^1.5); the scatter grid includes it");
    }
    for (size_t k = 0; k < res.sunTerms.size(); ++k) {
        const SunTerm& t = res.sunTerms[k];
        const std::string p = "sun_term_" + std::to_string(k) + "_";
        meta.insertMeta("lpm:" + p + "toward", openvdb::Vec3DMetadata(openvdb::Vec3d(t.toSun.x, t.toSun.y, t.toSun.z)));
        rgb(p + "irradiance", t.irradiance);
        dbl(p + "angle_deg", t.angularDiameterDeg);
        str(p + "source", t.fromEnvironment ? "environment hot pixel" : "--sun");
        str(p + "grid", sunTransmittanceGridName(int(k)));
    }
    str("settings", canonicalSettings(o));
    str("settings_digest", settingsDigest(o));
    return meta;
}

}  // namespace lpm
