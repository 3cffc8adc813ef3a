// Procedural test scenes shared by the core tests and benchmarks: heterogeneous volumes
// built in code (no files) and simple environments.
#pragma once

#include <cmath>
#include <vector>

#include "core/envmap.h"
#include "core/medium.h"
#include "core/rng.h"

namespace lpm::test {

enum class VolumeKind { Cloud, Plume, Shell };

/// n^3 voxels of size h, density shaped by `kind`, scaled so that the mean optical depth
/// along a grid line through the whole block is `tau` (sigma_t * length averaged).
inline Medium makeVolume(VolumeKind kind, int n, double tau, std::uint64_t seed = 7, double h = 1.0) {
    Medium m;
    m.nx = m.ny = m.nz = n;
    m.voxelSize = {h, h, h};
    m.sigmaT.assign(m.voxelCount(), 0.0f);
    Pcg32 rng(seed, 11);
    struct Blob {
        double x, y, z, r, w;
    };
    std::vector<Blob> blobs;
    const int nb = kind == VolumeKind::Cloud ? 24 : 12;
    for (int i = 0; i < nb; ++i) {
        Blob b;
        b.x = 0.25 + 0.5 * rng.uniform();
        b.y = kind == VolumeKind::Plume ? 0.1 + 0.8 * i / double(nb) : 0.25 + 0.5 * rng.uniform();
        b.z = 0.25 + 0.5 * rng.uniform();
        if (kind == VolumeKind::Plume) {
            b.x = 0.5 + 0.15 * std::sin(7.0 * b.y) + 0.05 * (rng.uniform() - 0.5);
            b.z = 0.5 + 0.1 * std::cos(5.0 * b.y);
        }
        b.r = 0.08 + 0.12 * rng.uniform();
        b.w = 0.5 + rng.uniform();
        blobs.push_back(b);
    }
    double sum = 0;
    for (int z = 0; z < n; ++z)
        for (int y = 0; y < n; ++y)
            for (int x = 0; x < n; ++x) {
                const double px = (x + 0.5) / n, py = (y + 0.5) / n, pz = (z + 0.5) / n;
                double d = 0;
                if (kind == VolumeKind::Shell) {
                    const double r = std::sqrt((px - .5) * (px - .5) + (py - .5) * (py - .5) + (pz - .5) * (pz - .5));
                    d = (r > 0.22 && r < 0.45) ? 1.0 + 0.5 * std::sin(20 * px) * std::cos(17 * pz) : 0.0;
                } else {
                    for (const Blob& b : blobs) {
                        const double q =
                            ((px - b.x) * (px - b.x) + (py - b.y) * (py - b.y) + (pz - b.z) * (pz - b.z)) / (b.r * b.r);
                        d += b.w * std::exp(-q);
                    }
                    d = std::max(0.0, d - 0.15);  // hard-ish edges and empty space
                }
                m.sigmaT[m.index(x, y, z)] = float(d);
                sum += d;
            }
    // Mean optical depth along a line through the block: mean(sigma) * n * h.
    const double meanSigma = sum / m.voxelCount();
    const double k = meanSigma > 0 ? tau / (meanSigma * n * h) : 0.0;
    for (float& s : m.sigmaT) s = float(s * k);
    return m;
}

/// Largest optical depth along any grid line parallel to an axis.
inline double maxLineOpticalDepth(const Medium& m) {
    double best = 0;
    const int N[3] = {m.nx, m.ny, m.nz};
    for (int a = 0; a < 3; ++a) {
        const int u = (a + 1) % 3, v = (a + 2) % 3;
        for (int j = 0; j < N[v]; ++j)
            for (int i = 0; i < N[u]; ++i) {
                double t = 0;
                for (int k = 0; k < N[a]; ++k) {
                    int idx[3];
                    idx[a] = k;
                    idx[u] = i;
                    idx[v] = j;
                    t += m.sigmaT[m.index(idx[0], idx[1], idx[2])] * m.voxelSize[a];
                }
                best = std::max(best, t);
            }
    }
    return best;
}

/// Rescales extinction so that the largest axis-line optical depth equals `tau`.
inline void scaleToMaxOpticalDepth(Medium& m, double tau) {
    const double k = tau / maxLineOpticalDepth(m);
    for (float& s : m.sigmaT) s = float(s * k);
}

/// Exact voxel average of exp(-sigma * distance to the box boundary along `toward`) for a
/// homogeneous box (independent of the solver: q^3 point quadrature, analytic distances).
inline double boxTransmittanceAverage(const Medium& m, double sigma, int ix, int iy, int iz, const Vec3& toward,
                                      int q) {
    double acc = 0;
    const double ext[3] = {m.nx * m.voxelSize.x, m.ny * m.voxelSize.y, m.nz * m.voxelSize.z};
    for (int a = 0; a < q; ++a)
        for (int b = 0; b < q; ++b)
            for (int c = 0; c < q; ++c) {
                const Vec3 p{(ix + (a + 0.5) / q) * m.voxelSize.x, (iy + (b + 0.5) / q) * m.voxelSize.y,
                             (iz + (c + 0.5) / q) * m.voxelSize.z};
                double t = 1e30;
                for (int k = 0; k < 3; ++k) {
                    if (toward[k] > 0) t = std::min(t, (ext[k] - p[k]) / toward[k]);
                    if (toward[k] < 0) t = std::min(t, -p[k] / toward[k]);
                }
                acc += std::exp(-sigma * t);
            }
    return acc / (q * q * q);
}

/// Uniform-sigma box of n^3 voxels.
inline Medium makeBox(int nx, int ny, int nz, double sigma, double h = 1.0) {
    Medium m;
    m.nx = nx;
    m.ny = ny;
    m.nz = nz;
    m.voxelSize = {h, h, h};
    m.sigmaT.assign(m.voxelCount(), float(sigma));
    return m;
}

/// A sky: blue-ish gradient above, dark ground below, a warm broad hot spot.
/// An odd-sized sparse block (a quarter of its tiles missing) with random extinction,
/// about 30% of the voxels empty, anisotropic voxels: the multi-resolution transfer's test block.
inline Medium sparseBlock(std::uint64_t seed) {
    Medium probe;
    probe.nx = 27;
    probe.ny = 19;
    probe.nz = 22;
    std::vector<std::uint8_t> active(size_t(probe.tilesX()) * probe.tilesY() * probe.tilesZ());
    for (size_t t = 0; t < active.size(); ++t) active[t] = t % 4 != 2;
    Medium m;
    m.allocate(probe.nx, probe.ny, probe.nz, &active);
    m.voxelSize = {0.5, 0.7, 0.6};
    Pcg32 rng(seed, 1);
    for (int z = 0; z < m.nz; ++z)
        for (int y = 0; y < m.ny; ++y)
            for (int x = 0; x < m.nx; ++x) {
                const size_t i = m.index(x, y, z);
                if (i != Medium::npos) m.sigmaT[i] = rng.uniform() < 0.3 ? 0.0f : float(3 * rng.uniform());
            }
    return m;
}

inline EnvMap makeSky(int width = 128) {
    const int height = width / 2;
    std::vector<RGB> px(size_t(width) * height);
    for (int y = 0; y < height; ++y)
        for (int x = 0; x < width; ++x) {
            const double lat = kPi / 2 - (y + 0.5) / height * kPi;
            const double lon = kPi - 2 * kPi * (x + 0.5) / width;
            const Vec3 d{std::cos(lat) * std::sin(lon), std::sin(lat), std::cos(lat) * std::cos(lon)};
            RGB c = lat > 0 ? RGB(0.35f, 0.5f, 0.9f) * float(0.6 + 0.4 * std::sin(lat)) : RGB(0.12f, 0.1f, 0.08f);
            const Vec3 spot = normalize(Vec3{0.6, 0.5, 0.3});
            const double cs = dot(d, spot);
            c += RGB(3.0f, 2.4f, 1.5f) * float(std::exp(-(1 - cs) * 20.0));
            px[size_t(y) * width + x] = c;
        }
    return EnvMap(width, height, std::move(px));
}

}  // namespace lpm::test
