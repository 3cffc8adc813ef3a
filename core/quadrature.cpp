#include "core/quadrature.h"

#include <algorithm>
#include <cmath>

#include "core/error.h"
#include "core/phase.h"

namespace lpm {

namespace {
inline double areaElement(double x, double y) { return std::atan2(x * y, std::sqrt(x * x + y * y + 1)); }

// Direction for face coordinates (u, v) in [-1, 1] on `face`.
inline Vec3 faceDir(int face, double u, double v) {
    const int a = CubeQuadrature::faceAxis(face);
    Vec3 d;
    d[a] = CubeQuadrature::faceSign(face);
    d[(a + 1) % 3] = u;
    d[(a + 2) % 3] = v;
    return normalize(d);
}
}  // namespace

double CubeQuadrature::rectSolidAngle(double u0, double v0, double u1, double v1) {
    return areaElement(u1, v1) - areaElement(u0, v1) - areaElement(u1, v0) + areaElement(u0, v0);
}

CubeQuadrature::CubeQuadrature(int n) : n_(n) {
    if (n < 1 || n > 64)
        throw Error("CubeQuadrature", "directions per face must be in 1..64, got " + std::to_string(n));
    dirs_.resize(count());
    weights_.resize(count());
    for (int f = 0; f < 6; ++f)
        for (int iu = 0; iu < n; ++iu)
            for (int iv = 0; iv < n; ++iv) {
                const int i = f * n * n + iu * n + iv;
                const double u0 = 2.0 * iu / n - 1, u1 = 2.0 * (iu + 1) / n - 1;
                const double v0 = 2.0 * iv / n - 1, v1 = 2.0 * (iv + 1) / n - 1;
                dirs_[i] = faceDir(f, 0.5 * (u0 + u1), 0.5 * (v0 + v1));
                weights_[i] = rectSolidAngle(u0, v0, u1, v1);
            }
}

int CubeQuadrature::indexOf(const Vec3& d) const {
    int a = 0;
    if (std::fabs(d.y) > std::fabs(d[a])) a = 1;
    if (std::fabs(d.z) > std::fabs(d[a])) a = 2;
    const double m = std::fabs(d[a]);
    const int face = 2 * a + (d[a] < 0 ? 1 : 0);
    const double u = d[(a + 1) % 3] / m, v = d[(a + 2) % 3] / m;
    const int iu = std::clamp(int(std::floor((u + 1) * 0.5 * n_)), 0, n_ - 1);
    const int iv = std::clamp(int(std::floor((v + 1) * 0.5 * n_)), 0, n_ - 1);
    return face * n_ * n_ + iu * n_ + iv;
}

void CubeQuadrature::subdivide(int i, int m, std::vector<Vec3>& dirs, std::vector<double>& weights) const {
    const int f = face(i), rem = i % (n_ * n_), iu = rem / n_, iv = rem % n_;
    dirs.clear();
    weights.clear();
    const double du = 2.0 / (n_ * m);
    for (int a = 0; a < m; ++a)
        for (int b = 0; b < m; ++b) {
            const double u0 = 2.0 * iu / n_ - 1 + a * du, v0 = 2.0 * iv / n_ - 1 + b * du;
            dirs.push_back(faceDir(f, u0 + 0.5 * du, v0 + 0.5 * du));
            weights.push_back(rectSolidAngle(u0, v0, u0 + du, v0 + du));
        }
}

std::vector<Vec3> coneDirections(const Vec3& w, double halfAngle, int k) {
    if (k <= 1 || halfAngle <= 0) return {w};
    Vec3 t, b;
    orthonormalBasis(w, t, b);
    std::vector<Vec3> out;
    const double cosMax = std::cos(halfAngle);
    const double golden = kPi * (3.0 - std::sqrt(5.0));
    for (int j = 0; j < k; ++j) {
        const double cosT = 1 - (j + 0.5) / k * (1 - cosMax);  // uniform in solid angle
        const double sinT = std::sqrt(std::max(0.0, 1 - cosT * cosT));
        const double phi = j * golden;
        out.push_back(t * (sinT * std::cos(phi)) + b * (sinT * std::sin(phi)) + w * cosT);
    }
    return out;
}

FormFactors::FormFactors(const CubeQuadrature& dirs, const CubeQuadrature* bins, double g) : g_(g) {
    const int nd = dirs.count();
    binCount_ = bins ? bins->count() : 1;
    binWeights_.resize(binCount_);
    binOfDir_.resize(nd);
    for (int d = 0; d < binCount_; ++d) binWeights_[d] = bins ? bins->weight(d) : kFourPi;
    for (int i = 0; i < nd; ++i) binOfDir_[i] = bins ? bins->indexOf(dirs.dir(i)) : 0;
    f_.assign(size_t(nd) * binCount_, 0.0);
    if (!bins) {
        std::fill(f_.begin(), f_.end(), 1.0);
        return;
    }
    if (g == 0.0) {  // isotropic phase: exact, no quadrature
        for (int i = 0; i < nd; ++i)
            for (int d = 0; d < binCount_; ++d) f_[size_t(i) * binCount_ + d] = binWeights_[d] / kFourPi;
        return;
    }
    // Fine target texels, each assigned to the bin containing it.
    // Resolution per face grows as the HG lobe narrows (width ~ 1 - |g|), capped at 64.
    const int b = bins->perFace();
    const int want = std::max(32, int(std::ceil(4.0 / std::max(1e-3, 1 - std::fabs(g)))));
    const int k = std::max(1, std::min((want + b - 1) / b, 64 / b));
    CubeQuadrature fineQ(b * k);
    fineDir_.resize(fineQ.count());
    fineW_.resize(fineQ.count());
    fineBin_.resize(fineQ.count());
    for (int t = 0; t < fineQ.count(); ++t) {
        fineDir_[t] = fineQ.dir(t);
        fineW_[t] = fineQ.weight(t);
        fineBin_[t] = bins->indexOf(fineQ.dir(t));
    }
    std::vector<Vec3> sd;
    std::vector<double> sw;
    for (int i = 0; i < nd; ++i) {
        dirs.subdivide(i, 4, sd, sw);
        integrateRow(sd, sw, &f_[size_t(i) * binCount_]);
    }
}

void FormFactors::integrateRow(const std::vector<Vec3>& src, const std::vector<double>& srcW, double* out) const {
    std::fill(out, out + binCount_, 0.0);
    double wsum = 0;
    for (double w : srcW) wsum += w;
    for (size_t s = 0; s < src.size(); ++s) {
        const double ws = srcW[s] / wsum;
        for (size_t t = 0; t < fineDir_.size(); ++t)
            out[fineBin_[t]] += ws * henyeyGreenstein(dot(src[s], fineDir_[t]), g_) * fineW_[t];
    }
    double total = 0;
    for (int d = 0; d < binCount_; ++d) total += out[d];
    for (int d = 0; d < binCount_; ++d) out[d] /= total;  // rows sum to 1: no energy made or lost
}

std::vector<double> FormFactors::rowForCone(const Vec3& w, double halfAngle) const {
    std::vector<double> row(binCount_, 1.0);
    if (binCount_ == 1) return row;
    if (g_ == 0.0) {
        for (int d = 0; d < binCount_; ++d) row[d] = binWeights_[d] / kFourPi;
        return row;
    }
    const std::vector<Vec3> src = coneDirections(w, halfAngle, halfAngle > 0 ? 64 : 1);
    integrateRow(src, std::vector<double>(src.size(), 1.0), row.data());
    return row;
}

}  // namespace lpm
