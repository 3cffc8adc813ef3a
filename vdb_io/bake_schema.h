// The bake's metadata schema, in one place (docs/output_format.md, "Metadata"): every
// lpm:* key a bake carries, its type and meaning, and the typed access used by the writer
// (baker/bake_metadata.cpp), `render`, `info`, the sidecar and validateBake. A key is
// written and read only through these constants, so a name or a type cannot drift
// between the writer and its readers.
#pragma once

#include <string>
#include <vector>

#include <openvdb/openvdb.h>

#include "core/envmap.h"
#include "core/math.h"

namespace lpm {

enum class MetaType { String, Double, Int, Int64, Bool, Vec3d, Vec3i };

/// "string", "double", "int32", "int64", "bool", "vec3d", "vec3i".
const char* metaTypeName(MetaType t);

/// One metadata key. `required`: every valid bake of format 2 has it; `shader`: a renderer
/// needs it to shade the bake (it goes into the sidecar's "shader" block).
struct MetaKey {
    std::string name;
    MetaType type;
    bool required;
    bool shader;
    std::string meaning;
};

namespace bakekey {
// What the file is and how to read it.
inline const MetaKey formatVersion{"lpm:format_version", MetaType::Int, true, true,
                                   "bake format (2: exact sun terms in sun_transmittance_K)"};
inline const MetaKey version{"lpm:version", MetaType::String, true, false, "the lpmbake that wrote it"};
inline const MetaKey shOrder{"lpm:sh_order", MetaType::Int, true, true, "SH order L of the sh_* grids"};
inline const MetaKey shCount{"lpm:sh_count", MetaType::Int, true, true, "(L + 1)^2 grids sh_0 .."};
inline const MetaKey shBasis{"lpm:sh_basis", MetaType::String, true, true, "the SH basis and index order"};
inline const MetaKey shGrids{"lpm:sh_grids", MetaType::String, true, false, "names and type of the SH grids"};
inline const MetaKey shNegativeLobes{"lpm:sh_negative_lobes", MetaType::String, true, false,
                                     "clamp S at zero when shading"};
inline const MetaKey quantity{"lpm:quantity", MetaType::String, true, false, "what S is"};
inline const MetaKey usage{"lpm:usage", MetaType::String, true, false, "how a renderer uses S"};
inline const MetaKey units{"lpm:units", MetaType::String, true, false, "units of S and lengths"};
inline const MetaKey frame{"lpm:frame", MetaType::String, true, true, "frame of SH directions: world"};
inline const MetaKey upAxis{"lpm:up_axis", MetaType::String, false, true,
                            "the scene's up axis, y or z (absent before --up-axis: y)"};
inline const MetaKey workingColorspace{"lpm:working_colorspace", MetaType::String, true, true,
                                       "OCIO colour space of every RGB value"};
// The medium.
inline const MetaKey densityGrid{"lpm:density_grid", MetaType::String, true, true,
                                 "name of the density grid (empty: --no-density)"};
inline const MetaKey densityScale{"lpm:density_scale", MetaType::Double, true, true,
                                  "sigma_t = density * density_scale per world unit"};
inline const MetaKey albedo{"lpm:albedo", MetaType::Vec3d, true, true, "single-scattering albedo RGB"};
inline const MetaKey g{"lpm:g", MetaType::Double, true, true, "Henyey-Greenstein asymmetry"};
inline const MetaKey phaseFunction{"lpm:phase_function", MetaType::String, true, false, "Henyey-Greenstein"};
inline const MetaKey rendererGrids{"lpm:renderer_grids", MetaType::Bool, false, true,
                                   "the constant-free grids extinction and source are written"};
// Lights.
inline const MetaKey envFile{"lpm:env_file", MetaType::String, false, false, "environment image"};
inline const MetaKey envColorspace{"lpm:env_colorspace", MetaType::String, false, false,
                                   "colour space the environment was read as"};
inline const MetaKey envRotateYDeg{"lpm:env_rotate_y_deg", MetaType::Double, false, true,
                                   "environment turn about the up axis, degrees"};
inline const MetaKey envScale{"lpm:env_scale", MetaType::Double, false, true, "environment radiance factor"};
inline const MetaKey envOrientation{"lpm:env_orientation", MetaType::String, false, false,
                                    "lat-long convention of the environment"};
inline const MetaKey sunCount{"lpm:sun_count", MetaType::Int, true, false, "--sun lights"};
inline const MetaKey suns{"lpm:suns", MetaType::String, false, false, "the --sun lights, in words"};
inline const MetaKey temperatureGrid{"lpm:temperature_grid", MetaType::String, false, false, ""};
inline const MetaKey temperatureScale{"lpm:temperature_scale", MetaType::Double, false, false, ""};
inline const MetaKey temperatureOffset{"lpm:temperature_offset", MetaType::Double, false, false, ""};
inline const MetaKey temperatureIntensity{"lpm:temperature_intensity", MetaType::Double, false, false, ""};
inline const MetaKey temperatureConvention{"lpm:temperature_convention", MetaType::String, false, false, ""};
inline const MetaKey emissionGrid{"lpm:emission_grid", MetaType::String, false, false, "input emission grid"};
inline const MetaKey emissionScale{"lpm:emission_scale", MetaType::Double, false, false, ""};
inline const MetaKey emissionConvention{"lpm:emission_convention", MetaType::String, false, false, ""};
inline const MetaKey lights{"lpm:lights", MetaType::String, true, false, "every light, in words"};
// Solver settings and what it did.
inline const MetaKey quality{"lpm:quality", MetaType::String, false, false,
                             "--quality preset: preview, default or production (explicit knobs override it)"};
inline const MetaKey directionsPerFace{"lpm:directions_per_face", MetaType::Int, true, false, ""};
inline const MetaKey raysPerVoxel{"lpm:rays_per_voxel", MetaType::Int, true, false, ""};
inline const MetaKey raysHigherOrders{"lpm:rays_higher_orders", MetaType::Int, true, false, ""};
inline const MetaKey binsPerFace{"lpm:bins_per_face", MetaType::Int, true, false, ""};
inline const MetaKey tolerance{"lpm:tolerance", MetaType::Double, true, false, ""};
inline const MetaKey maxOrders{"lpm:max_orders", MetaType::Int, true, false, ""};
inline const MetaKey subdivide{"lpm:subdivide", MetaType::Int, true, false, ""};
inline const MetaKey multires{"lpm:multires", MetaType::String, true, false, "auto, on or off"};
inline const MetaKey multiresAfter{"lpm:multires_after", MetaType::Int, true, false, ""};
inline const MetaKey separableSources{"lpm:separable_sources", MetaType::String, true, false, "auto, on or off"};
inline const MetaKey sourceShape{"lpm:source_shape", MetaType::String, true, false, "auto, linear, constant"};
inline const MetaKey deltaM{"lpm:delta_m", MetaType::String, true, false, "auto, on or off"};
inline const MetaKey envHotShare{"lpm:env_hot_share", MetaType::Double, true, false, ""};
inline const MetaKey solveScale{"lpm:solve_scale", MetaType::Double, true, false, ""};
inline const MetaKey solveGridDims{"lpm:solve_grid_dims", MetaType::Vec3i, true, false, ""};
inline const MetaKey solveVoxelSize{"lpm:solve_voxel_size", MetaType::Vec3d, true, false, ""};
inline const MetaKey krylov{"lpm:krylov", MetaType::Bool, true, false, "GMRES acceleration allowed"};
inline const MetaKey solver{"lpm:solver", MetaType::String, true, false, "the method, in words"};
inline const MetaKey passes{"lpm:passes", MetaType::Int, true, false, "sweep passes run"};
inline const MetaKey residual{"lpm:residual", MetaType::Double, true, false, ""};
inline const MetaKey converged{"lpm:converged", MetaType::Bool, true, false, ""};
inline const MetaKey decisions{"lpm:decisions", MetaType::String, true, false, "the effect plan and events"};
inline const MetaKey inputFile{"lpm:input_file", MetaType::String, true, false, ""};
inline const MetaKey inputGrid{"lpm:input_grid", MetaType::String, true, false, ""};
inline const MetaKey inputGridIndex{"lpm:input_grid_index", MetaType::Int, true, false, ""};
inline const MetaKey empty{"lpm:empty", MetaType::Bool, true, false, "no active density"};
inline const MetaKey sanitizedValues{"lpm:sanitized_values", MetaType::Int64, true, false, "NaN/Inf set to 0"};
inline const MetaKey storage{"lpm:storage", MetaType::String, true, false, "float32 or half"};
inline const MetaKey timeReadS{"lpm:time_read_s", MetaType::Double, true, false, ""};
inline const MetaKey timeEnvS{"lpm:time_env_s", MetaType::Double, true, false, ""};
inline const MetaKey timeSolveS{"lpm:time_solve_s", MetaType::Double, true, false, ""};
inline const MetaKey timings{"lpm:timings", MetaType::String, true, false, ""};
inline const MetaKey commandLine{"lpm:command_line", MetaType::String, false, false, ""};
inline const MetaKey settings{"lpm:settings", MetaType::String, true, false, "canonical settings"};
inline const MetaKey settingsDigest{"lpm:settings_digest", MetaType::String, true, false, "--skip-existing"};
// Exact sun terms (core/sun_term.h); the per-term keys are sunTermKey(k, field).
inline const MetaKey sunTermCount{"lpm:sun_term_count", MetaType::Int, true, true, "exact sun terms"};
inline const MetaKey sunTermG{"lpm:sun_term_g", MetaType::Double, false, true, "g of the sun terms' phase"};
inline const MetaKey sunTermConvention{"lpm:sun_term_convention", MetaType::String, false, false, ""};
// The self-check (--verify, core/verify.h, docs/verify.md); present only when it ran.
inline const MetaKey verifyError{"lpm:verify_error", MetaType::Double, false, false,
                                 "estimated contribution-weighted relative RMS error of band 0"};
inline const MetaKey verifyErrorLow{"lpm:verify_error_low", MetaType::Double, false, false, "its interval's low end"};
inline const MetaKey verifyErrorHigh{"lpm:verify_error_high", MetaType::Double, false, false,
                                     "its interval's high end"};
inline const MetaKey verifyConfidence{"lpm:verify_confidence", MetaType::Double, false, false, "interval level"};
inline const MetaKey verifyProbes{"lpm:verify_probes", MetaType::Int, false, false, "Monte Carlo probes"};
inline const MetaKey verifyPaths{"lpm:verify_paths", MetaType::Int, false, false, "paths per probe"};
inline const MetaKey verifyNoise{"lpm:verify_mc_noise", MetaType::Double, false, false, "the probes' own noise"};
inline const MetaKey verifySeconds{"lpm:time_verify_s", MetaType::Double, false, false,
                                   "time of the check (volatile: not in the content digest)"};
inline const MetaKey verifyMaxError{"lpm:verify_max_error", MetaType::Double, false, false, "--max-error"};
inline const MetaKey verifyFailed{"lpm:verify_failed", MetaType::Bool, false, false,
                                  "the error is above --max-error: re-bake with a higher --quality"};
}  // namespace bakekey

/// Fields of exact sun term K, keys lpm:sun_term_K_<field>.
enum class SunTermField { Toward, Irradiance, AngleDeg, Source, Grid };
/// The key of field `f` of sun term k (type: Vec3d for Toward/Irradiance, Double for
/// AngleDeg, String for Source/Grid; all required for k < sun_term_count, for shaders).
MetaKey sunTermKey(int k, SunTermField f);

/// Every fixed key above (not the per-sun-term keys), in the order of the list.
const std::vector<MetaKey>& bakeSchema();

/// Typed writers: throw std::logic_error when the key's type differs (a programming error).
void putString(openvdb::MetaMap& m, const MetaKey& k, const std::string& v);
void putDouble(openvdb::MetaMap& m, const MetaKey& k, double v);
void putInt(openvdb::MetaMap& m, const MetaKey& k, int v);
void putInt64(openvdb::MetaMap& m, const MetaKey& k, std::int64_t v);
void putBool(openvdb::MetaMap& m, const MetaKey& k, bool v);
void putVec3(openvdb::MetaMap& m, const MetaKey& k, double x, double y, double z);
void putVec3i(openvdb::MetaMap& m, const MetaKey& k, int x, int y, int z);

/// Typed readers: the value, or `fallback` when the key is absent or of another type.
std::string getString(const openvdb::MetaMap& m, const MetaKey& k, const std::string& fallback = "");
double getDouble(const openvdb::MetaMap& m, const MetaKey& k, double fallback);
int getInt(const openvdb::MetaMap& m, const MetaKey& k, int fallback);
bool getBool(const openvdb::MetaMap& m, const MetaKey& k, bool fallback);
RGB getRgb(const openvdb::MetaMap& m, const MetaKey& k, const RGB& fallback);
Vec3 getVec3(const openvdb::MetaMap& m, const MetaKey& k, const Vec3& fallback);

/// True when `m` holds key k with k's type.
bool hasKey(const openvdb::MetaMap& m, const MetaKey& k);

/// Problems with the schema: keys of the wrong type, sun terms without their fields, and
/// missing keys: with `complete`, every required key (what this lpmbake writes); without,
/// the required keys a shader needs (what every bake since format 1 has). Empty when fine.
std::vector<std::string> schemaProblems(const openvdb::MetaMap& m, bool complete);

/// What a shader needs, read from the metadata (the sidecar's "shader" block).
struct ShaderSun {
    Vec3 toward;  ///< unit, toward the sun
    RGB irradiance;
    double angleDeg = 0;
    std::string grid;  ///< its transmittance grid
};
struct ShaderParams {
    int formatVersion = 0;
    std::string densityGrid = "density";
    double densityScale = 1;
    RGB albedo{0.9f, 0.9f, 0.9f};
    double g = 0;
    int shOrder = 0;
    std::string workingColorspace = "ACEScg";
    UpAxis up = UpAxis::Y;
    double envRotateYDeg = 0, envScale = 1;
    bool rendererGrids = false;
    double sunTermG = 0;
    std::vector<ShaderSun> sunTerms;
};
ShaderParams readShaderParams(const openvdb::MetaMap& m);

}  // namespace lpm
