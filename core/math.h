// Small vector, matrix and colour types shared by the solver and the Monte Carlo
// reference. Directions are unit Vec3 in double precision; per-voxel storage is float.
#pragma once

#include <array>
#include <cmath>
#include <cstddef>

namespace lpm {

constexpr double kPi = 3.14159265358979323846;
constexpr double kFourPi = 4.0 * kPi;
constexpr double kInv4Pi = 1.0 / kFourPi;

struct Vec3 {
    double x = 0, y = 0, z = 0;
    Vec3() = default;
    constexpr Vec3(double x_, double y_, double z_) : x(x_), y(y_), z(z_) {}
    double operator[](int i) const { return i == 0 ? x : (i == 1 ? y : z); }
    double& operator[](int i) { return i == 0 ? x : (i == 1 ? y : z); }
    Vec3 operator+(const Vec3& o) const { return {x + o.x, y + o.y, z + o.z}; }
    Vec3 operator-(const Vec3& o) const { return {x - o.x, y - o.y, z - o.z}; }
    Vec3 operator-() const { return {-x, -y, -z}; }
    Vec3 operator*(double s) const { return {x * s, y * s, z * s}; }
    Vec3 operator/(double s) const { return {x / s, y / s, z / s}; }
};
inline double dot(const Vec3& a, const Vec3& b) { return a.x * b.x + a.y * b.y + a.z * b.z; }
inline Vec3 cross(const Vec3& a, const Vec3& b) {
    return {a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x};
}
inline double length(const Vec3& a) { return std::sqrt(dot(a, a)); }
inline Vec3 normalize(const Vec3& a) { return a / length(a); }

/// Orthonormal basis (t, b) around unit n (Duff et al. 2017).
inline void orthonormalBasis(const Vec3& n, Vec3& t, Vec3& b) {
    const double s = std::copysign(1.0, n.z);
    const double a = -1.0 / (s + n.z);
    const double c = n.x * n.y * a;
    t = {1.0 + s * n.x * n.x * a, s * c, -s * n.x};
    b = {c, s + n.y * n.y * a, -n.y};
}

/// Row-major 3x3 matrix.
struct Mat3 {
    std::array<double, 9> m{1, 0, 0, 0, 1, 0, 0, 0, 1};
    static Mat3 identity() { return Mat3{}; }
    Vec3 operator*(const Vec3& v) const {
        return {m[0] * v.x + m[1] * v.y + m[2] * v.z, m[3] * v.x + m[4] * v.y + m[5] * v.z,
                m[6] * v.x + m[7] * v.y + m[8] * v.z};
    }
    Mat3 transposed() const {
        Mat3 t;
        for (int r = 0; r < 3; ++r)
            for (int c = 0; c < 3; ++c) t.m[r * 3 + c] = m[c * 3 + r];
        return t;
    }
    Mat3 operator*(const Mat3& o) const {
        Mat3 r;
        for (int i = 0; i < 3; ++i)
            for (int j = 0; j < 3; ++j) {
                double s = 0;
                for (int k = 0; k < 3; ++k) s += m[i * 3 + k] * o.m[k * 3 + j];
                r.m[i * 3 + j] = s;
            }
        return r;
    }
    /// Rotation by `radians` about unit axis (right-handed).
    static Mat3 rotation(const Vec3& axis, double radians) {
        const Vec3 a = normalize(axis);
        const double c = std::cos(radians), s = std::sin(radians), t = 1 - c;
        Mat3 r;
        r.m = {t * a.x * a.x + c,       t * a.x * a.y - s * a.z, t * a.x * a.z + s * a.y,
               t * a.x * a.y + s * a.z, t * a.y * a.y + c,       t * a.y * a.z - s * a.x,
               t * a.x * a.z - s * a.y, t * a.y * a.z + s * a.x, t * a.z * a.z + c};
        return r;
    }
};

/// Linear RGB triple in the working colour space.
struct RGB {
    float r = 0, g = 0, b = 0;
    RGB() = default;
    constexpr RGB(float r_, float g_, float b_) : r(r_), g(g_), b(b_) {}
    explicit constexpr RGB(float v) : r(v), g(v), b(v) {}
    float operator[](int i) const { return i == 0 ? r : (i == 1 ? g : b); }
    float& operator[](int i) { return i == 0 ? r : (i == 1 ? g : b); }
    RGB operator+(const RGB& o) const { return {r + o.r, g + o.g, b + o.b}; }
    RGB operator*(const RGB& o) const { return {r * o.r, g * o.g, b * o.b}; }
    RGB operator*(float s) const { return {r * s, g * s, b * s}; }
    RGB& operator+=(const RGB& o) {
        r += o.r;
        g += o.g;
        b += o.b;
        return *this;
    }
    float maxComponent() const { return std::fmax(r, std::fmax(g, b)); }
    float average() const { return (r + g + b) / 3.0f; }
    bool isBlack() const { return r == 0 && g == 0 && b == 0; }
};

/// (1 - exp(-tau)) / tau, accurate for all tau >= 0 (tends to 1 as tau -> 0; no 0/0).
inline double phi1(double tau) {
    if (tau < 1e-4) return 1.0 - tau * (0.5 - tau / 6.0);
    return -std::expm1(-tau) / tau;
}
/// (tau - (1 - exp(-tau))) / tau^2, accurate for all tau >= 0 (tends to 1/2 as tau -> 0).
inline double phi2(double tau) {
    if (tau < 1e-3) return 0.5 - tau * (1.0 / 6.0 - tau / 24.0);
    return (tau + std::expm1(-tau)) / (tau * tau);
}

}  // namespace lpm
