// OpenColorIO glue: config lookup, colour-space conversion and display encoding.
#include "vdb_io/color.h"

#include <unistd.h>

#include <cstdlib>
#include <filesystem>
#include <map>
#include <mutex>

#include <OpenColorIO/OpenColorIO.h>

#include "core/parallel.h"
#include "vdb_io/io_error.h"

namespace OCIO = OCIO_NAMESPACE;

namespace lpm {

namespace {

const char* kComp = "color";

std::string exeDir() {
    std::error_code ec;
    const auto p = std::filesystem::read_symlink("/proc/self/exe", ec);
    return ec ? std::string() : p.parent_path().string();
}

/// Loads (once per path) and validates the config in use.
OCIO::ConstConfigRcPtr config() {
    static std::mutex mu;
    static std::map<std::string, OCIO::ConstConfigRcPtr> cache;
    const std::string path = ocioConfigPath();
    std::lock_guard<std::mutex> lock(mu);
    auto it = cache.find(path);
    if (it != cache.end()) return it->second;
    try {
        OCIO::ConstConfigRcPtr cfg = OCIO::Config::CreateFromFile(path.c_str());
        cfg->validate();
        cache[path] = cfg;
        return cfg;
    } catch (const OCIO::Exception& e) {
        throw InputError(kComp, "cannot load OCIO config '" + path + "': " + e.what());
    }
}

void applyPacked(const OCIO::ConstCPUProcessorRcPtr& cpu, std::vector<float>& rgb) {
    // CPUProcessor::apply is thread-safe; run rows of 4096 pixels in parallel.
    const size_t pixels = rgb.size() / 3;
    parallelForChunks(pixels, 4096, [&](size_t b, size_t e) {
        OCIO::PackedImageDesc desc(rgb.data() + b * 3, long(e - b), 1, 3);
        cpu->apply(desc);
    });
}

}  // namespace

std::string ocioConfigPath() {
    if (const char* env = std::getenv("OCIO"); env && *env) return env;  // $OCIO wins
    const std::string dir = exeDir();
    std::vector<std::string> candidates;
    if (!dir.empty()) {
        candidates.push_back(dir + "/../share/lpmbake/config.ocio");  // installed
        candidates.push_back(dir + "/../data/config.ocio");
    }
#ifdef LPM_SOURCE_DATA_DIR
    candidates.push_back(std::string(LPM_SOURCE_DATA_DIR) + "/config.ocio");  // build tree
#endif
    for (const auto& c : candidates)
        if (std::filesystem::exists(c)) return std::filesystem::weakly_canonical(c).string();
    std::string tried;
    for (const auto& c : candidates) tried += " " + c;
    throw InputError(
        kComp, "no OCIO config: $OCIO is not set and the shipped config.ocio was not found (looked at" + tried + ")");
}

std::vector<std::string> colorSpaceNames() {
    auto cfg = config();
    std::vector<std::string> names;
    for (int i = 0; i < cfg->getNumColorSpaces(); ++i) names.push_back(cfg->getColorSpaceNameByIndex(i));
    return names;
}

bool colorSpaceKnown(const std::string& name) {
    return !name.empty() && config()->getColorSpace(name.c_str()) != nullptr;
}

std::string canonicalColorSpace(const std::string& name) {
    auto cfg = config();
    auto cs = name.empty() ? nullptr : cfg->getColorSpace(name.c_str());
    if (!cs) {
        std::string known;
        for (const auto& n : colorSpaceNames()) known += (known.empty() ? "" : ", ") + n;
        throw InputError(kComp, "colour space '" + name + "' is not in the OCIO config '" + ocioConfigPath() +
                                    "' (known: " + known + ")");
    }
    return cs->getName();
}

void convertColor(std::vector<float>& rgb, const std::string& src, const std::string& dst) {
    const std::string s = canonicalColorSpace(src), d = canonicalColorSpace(dst);
    if (s == d) return;
    try {
        applyPacked(config()->getProcessor(s.c_str(), d.c_str())->getDefaultCPUProcessor(), rgb);
    } catch (const OCIO::Exception& e) {
        throw InputError(kComp, "cannot convert '" + s + "' to '" + d + "': " + e.what());
    }
}

void convertToDisplay(std::vector<float>& rgb, const std::string& src, const std::string& display,
                      const std::string& view) {
    auto cfg = config();
    const std::string s = canonicalColorSpace(src);
    const std::string disp = display.empty() ? cfg->getDefaultDisplay() : display;
    const std::string v = view.empty() ? cfg->getDefaultView(disp.c_str()) : view;
    try {
        auto t = OCIO::DisplayViewTransform::Create();
        t->setSrc(s.c_str());
        t->setDisplay(disp.c_str());
        t->setView(v.c_str());
        applyPacked(cfg->getProcessor(t)->getDefaultCPUProcessor(), rgb);
    } catch (const OCIO::Exception& e) {
        throw InputError(kComp, "cannot convert '" + s + "' to display '" + disp + "' view '" + v + "': " + e.what());
    }
}

}  // namespace lpm
