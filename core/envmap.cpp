#include "core/envmap.h"

#include <algorithm>
#include <cmath>

#include "core/error.h"
#include "core/parallel.h"

namespace lpm {

namespace {
// Polar angle from +Y of row boundary k (0 = top).
inline double rowTheta(double k, int height) { return k * kPi / height; }
// Direction toward light for image coordinates (u in [0,1] across, theta polar from +Y).
inline Vec3 dirFromUTheta(double u, double theta) {
    const double lon = kPi - 2 * kPi * u;
    const double s = std::sin(theta);
    return {s * std::sin(lon), std::cos(theta), s * std::cos(lon)};
}
}  // namespace

Vec3 upAxisToWorld(UpAxis a, const Vec3& d) { return a == UpAxis::Z ? Vec3(d.x, -d.z, d.y) : d; }

namespace {
std::vector<float> interleaved(const std::vector<RGB>& pixels) {
    std::vector<float> rgb;
    rgb.reserve(pixels.size() * 3);
    for (const RGB& p : pixels) rgb.insert(rgb.end(), {p.r, p.g, p.b});
    return rgb;
}
}  // namespace

EnvMap::EnvMap(int width, int height, std::vector<RGB> pixels, double rotateYDegrees, float scale, UpAxis up)
    : EnvMap(width, height,
             pixels.size() == size_t(std::max(width, 0)) * size_t(std::max(height, 0))
                 ? interleaved(pixels)
                 : std::vector<float>(1),  // refused below
             rotateYDegrees, scale, up) {}

EnvMap::EnvMap(int width, int height, std::vector<float> rgb, double rotateYDegrees, float scale, UpAxis up)
    : width_(width), height_(height), rgb_(std::move(rgb)) {
    if (width_ <= 0 || height_ <= 0 || rgb_.size() != size_t(width_) * height_ * 3)
        throw Error("EnvMap", "bad image size " + std::to_string(width_) + "x" + std::to_string(height_));
    const Mat3 spin = Mat3::rotation({0, 1, 0}, rotateYDegrees * kPi / 180.0);
    const Mat3 upTurn = up == UpAxis::Z ? Mat3::rotation({1, 0, 0}, kPi / 2) : Mat3::identity();
    rot_ = upTurn * spin;
    rotInv_ = rot_.transposed();
    // Each row checked, scaled and summed (mean RGB x solid angle, left to right) on its
    // own, over the threads; the marginal over rows after, in row order.
    const size_t H = size_t(height_), W = size_t(width_);
    std::vector<double> rowSum(H, 0.0);
    std::vector<float> rowMax(H, 0.f), rowBad(H, 0.f);
    std::vector<unsigned char> rowHasBad(H, 0);
    parallelForChunks(H, 8, [&](size_t yb, size_t ye) {
        for (size_t y = yb; y < ye; ++y) {
            const double omega = pixelSolidAngle(int(y));
            double sum = 0;
            float most = 0;
            for (float* v = &rgb_[y * W * 3]; v != &rgb_[y * W * 3] + W * 3; v += 3) {
                for (int c = 0; c < 3; ++c)
                    if ((!std::isfinite(v[c]) || v[c] < 0) && !rowHasBad[y]) {
                        rowHasBad[y] = 1;
                        rowBad[y] = v[c];
                    }
                const RGB p = RGB(v[0], v[1], v[2]) * scale;
                v[0] = p.r;
                v[1] = p.g;
                v[2] = p.b;
                most = std::max(most, p.maxComponent());
                sum += double(p.average()) * omega;
            }
            rowSum[y] = sum;
            rowMax[y] = most;
        }
    });
    for (size_t y = 0; y < H; ++y)
        if (rowHasBad[y])
            throw Error("EnvMap",
                        "pixel value " + std::to_string(rowBad[y]) + " is not a finite non-negative radiance");
    rowCdf_.assign(H + 1, 0.0);
    for (size_t y = 0; y < H; ++y) {
        rowCdf_[y + 1] = rowCdf_[y] + rowSum[y];
        maxValue_ = std::max(maxValue_, rowMax[y]);
    }
    total_ = rowCdf_[H];
}

void EnvMap::releasePixels() {
    std::vector<float>().swap(rgb_);
    colCdf_.reset();
    released_ = true;
}

void EnvMap::requirePixels() const {
    if (released_) throw Error("EnvMap", "the pixels were released after binning; this read needs them");
}

double EnvMap::pixelSolidAngle(int y) const {
    return (2 * kPi / width_) * (std::cos(rowTheta(y, height_)) - std::cos(rowTheta(y + 1, height_)));
}

const std::vector<double>& EnvMap::columnCdf() const {
    requirePixels();
    std::shared_ptr<const std::vector<double>> have = std::atomic_load(&colCdf_);
    if (have) return *have;
    const size_t W = size_t(width_);
    auto cdfs = std::make_shared<std::vector<double>>(size_t(height_) * (W + 1), 0.0);
    parallelForChunks(size_t(height_), 8, [&](size_t yb, size_t ye) {
        for (size_t y = yb; y < ye; ++y) {
            const double omega = pixelSolidAngle(int(y));
            double* cdf = &(*cdfs)[y * (W + 1)];
            for (size_t x = 0; x < W; ++x) cdf[x + 1] = cdf[x] + double(at(y * W + x).average()) * omega;
        }
    });
    std::shared_ptr<const std::vector<double>> built = std::move(cdfs);
    // The first table stored is kept (a reference to it may already be in use).
    if (!std::atomic_compare_exchange_strong(&colCdf_, &have, built)) return *have;
    return *built;
}

EnvMap EnvMap::constant(const RGB& radiance) { return EnvMap(2, 1, {radiance, radiance}); }

void EnvMap::pixelOf(const Vec3& towardLight, int& px, int& py) const {
    requirePixels();
    const Vec3 d = toImage(towardLight);
    const double len = length(d);
    const double lat = std::asin(std::clamp(d.y / len, -1.0, 1.0));
    const double lon = std::atan2(d.x, d.z);
    const double u = (kPi - lon) / (2 * kPi);
    const double v = (kPi / 2 - lat) / kPi;
    px = std::clamp(int(std::floor(u * width_)), 0, width_ - 1);
    py = std::clamp(int(std::floor(v * height_)), 0, height_ - 1);
}

RGB EnvMap::lookup(const Vec3& towardLight) const {
    int px, py;
    pixelOf(towardLight, px, py);
    return pixel(px, py);
}

RGB EnvMap::lookupSmooth(const Vec3& towardLight) const {
    const Vec3 d = toImage(towardLight);
    const double len = length(d);
    const double lat = std::asin(std::clamp(d.y / len, -1.0, 1.0));
    const double u = (kPi - std::atan2(d.x, d.z)) / (2 * kPi) * width_ - 0.5;
    const double v = std::clamp((kPi / 2 - lat) / kPi * height_ - 0.5, 0.0, double(height_ - 1));
    const int x0 = int(std::floor(u)), y0 = int(std::floor(v));
    const double fx = u - x0, fy = v - y0;
    const int y1 = std::min(y0 + 1, height_ - 1);
    auto px = [&](int x, int y) { return pixel(((x % width_) + width_) % width_, y); };
    RGB out;
    for (int c = 0; c < 3; ++c)
        out[c] = float((1 - fy) * ((1 - fx) * px(x0, y0)[c] + fx * px(x0 + 1, y0)[c]) +
                       fy * ((1 - fx) * px(x0, y1)[c] + fx * px(x0 + 1, y1)[c]));
    return out;
}

double EnvMap::pdf(const Vec3& towardLight) const {
    if (total_ <= 0) return 0;
    int px, py;
    pixelOf(towardLight, px, py);
    const double* cdf = &columnCdf()[size_t(py) * (width_ + 1)];
    return (cdf[px + 1] - cdf[px]) / total_ / pixelSolidAngle(py);
}

RGB EnvMap::sample(double u1, double u2, Vec3& towardLight, double& pdfOut) const {
    if (total_ <= 0) {
        pdfOut = 0;
        return RGB(0.f);
    }
    // Row.
    const double t1 = u1 * total_;
    int y = int(std::upper_bound(rowCdf_.begin(), rowCdf_.end(), t1) - rowCdf_.begin()) - 1;
    y = std::clamp(y, 0, height_ - 1);
    while (rowCdf_[y + 1] - rowCdf_[y] <= 0 && y > 0) --y;  // never land on an empty row
    while (rowCdf_[y + 1] - rowCdf_[y] <= 0 && y < height_ - 1) ++y;
    const double rowMass = rowCdf_[y + 1] - rowCdf_[y];
    const double fy = std::clamp((t1 - rowCdf_[y]) / rowMass, 0.0, 1.0);
    // Column, reusing the remainder of u1 would correlate; use u2 for the column and
    // split the fractional part of the row sample for the in-pixel position.
    const double* cdf = &columnCdf()[size_t(y) * (width_ + 1)];
    const double t2 = u2 * cdf[width_];
    int x = int(std::upper_bound(cdf, cdf + width_ + 1, t2) - cdf) - 1;
    x = std::clamp(x, 0, width_ - 1);
    while (cdf[x + 1] - cdf[x] <= 0 && x > 0) --x;
    while (cdf[x + 1] - cdf[x] <= 0 && x < width_ - 1) ++x;
    const double fx = std::clamp((t2 - cdf[x]) / (cdf[x + 1] - cdf[x]), 0.0, 1.0);
    // Uniform in solid angle inside the pixel: u uniform, cos(theta) uniform.
    const double c0 = std::cos(rowTheta(y, height_)), c1 = std::cos(rowTheta(y + 1, height_));
    const double cosT = c0 + fy * (c1 - c0);
    const double theta = std::acos(std::clamp(cosT, -1.0, 1.0));
    const double u = (x + fx) / width_;
    towardLight = toWorld(dirFromUTheta(u, theta));
    const double omega = (2 * kPi / width_) * (c0 - c1);
    pdfOut = (cdf[x + 1] - cdf[x]) / total_ / omega;
    return pixel(x, y);
}

std::vector<EnvHotPixel> EnvMap::hotPixels(double minShare, int maxCount) const {
    requirePixels();
    std::vector<EnvHotPixel> hot;
    if (total_ <= 0 || maxCount <= 0) return hot;
    // A pixel's share is its step of its row's cumulative sum (as sample() draws it),
    // recomputed here row by row over the threads; the rows' finds joined in row order.
    const size_t H = size_t(height_), W = size_t(width_);
    std::vector<std::vector<EnvHotPixel>> rowHot(H);
    parallelForChunks(H, 8, [&](size_t yb, size_t ye) {
        for (size_t y = yb; y < ye; ++y) {
            const double omega = pixelSolidAngle(int(y));
            double cdf = 0;
            for (size_t x = 0; x < W; ++x) {
                const double next = cdf + double(at(y * W + x).average()) * omega;
                const double share = (next - cdf) / total_;
                cdf = next;
                if (!(share >= minShare)) continue;
                const double c0 = std::cos(rowTheta(int(y), height_)), c1 = std::cos(rowTheta(int(y) + 1, height_));
                EnvHotPixel h;
                h.x = int(x);
                h.y = int(y);
                h.omega = omega;
                h.toward = toWorld(dirFromUTheta((double(x) + 0.5) / width_, std::acos(0.5 * (c0 + c1))));
                h.radiance = at(y * W + x);
                h.share = share;
                rowHot[y].push_back(h);
            }
        }
    });
    for (auto& r : rowHot) hot.insert(hot.end(), r.begin(), r.end());
    std::stable_sort(hot.begin(), hot.end(),
                     [](const EnvHotPixel& a, const EnvHotPixel& b) { return a.share > b.share; });
    if (hot.size() > size_t(maxCount)) hot.resize(size_t(maxCount));
    return hot;
}

}  // namespace lpm
