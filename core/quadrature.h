// Cube-map direction quadrature for the six LPM sweep families (Fattal 2009, sec. 4):
// face f = 2*axis + (sign < 0), n x n texels per face at texel centres
// ((i + 0.5) / n) * 2 - 1, each weighted by its exact solid angle (weights sum to 4 pi).
// Also the form factors F^{i,d} (share of light travelling in bin i scattered into bin d).
#pragma once

#include <vector>

#include "core/math.h"

namespace lpm {

class CubeQuadrature {
public:
    explicit CubeQuadrature(int n);
    int perFace() const { return n_; }
    int count() const { return 6 * n_ * n_; }
    const Vec3& dir(int i) const { return dirs_[i]; }
    double weight(int i) const { return weights_[i]; }
    static int faceAxis(int face) { return face / 2; }
    static int faceSign(int face) { return (face % 2) ? -1 : 1; }
    int face(int i) const { return i / (n_ * n_); }
    /// Index of the texel containing direction d (any length > 0).
    int indexOf(const Vec3& d) const;
    /// m x m sub-directions of texel i with their exact solid angles (sum = weight(i)).
    void subdivide(int i, int m, std::vector<Vec3>& dirs, std::vector<double>& weights) const;

    /// Exact solid angle of the rectangle [u0,u1]x[v0,v1] on a cube face at distance 1.
    static double rectSolidAngle(double u0, double v0, double u1, double v1);

private:
    int n_;
    std::vector<Vec3> dirs_;
    std::vector<double> weights_;
};

/// Form factors from directions to the unshot bins for Henyey-Greenstein phase g:
/// row i holds Int_{bin d} p(w, w_i) dw averaged over the source region; rows sum to 1.
class FormFactors {
public:
    /// bins == nullptr means one isotropic bin.
    FormFactors(const CubeQuadrature& dirs, const CubeQuadrature* bins, double g);
    int binCount() const { return binCount_; }
    double binWeight(int d) const { return binWeights_[d]; }
    int binOfDirection(int i) const { return binOfDir_[i]; }
    const double* row(int i) const { return &f_[size_t(i) * binCount_]; }
    /// Row for a cone of directions of half-angle `halfAngle` around unit `w` (a sun).
    std::vector<double> rowForCone(const Vec3& w, double halfAngle) const;

private:
    void integrateRow(const std::vector<Vec3>& src, const std::vector<double>& srcW, double* out) const;
    int binCount_;
    double g_;
    std::vector<double> binWeights_;
    std::vector<int> binOfDir_;
    std::vector<double> f_;
    std::vector<Vec3> fineDir_;
    std::vector<double> fineW_;
    std::vector<int> fineBin_;
};

/// Directions uniformly covering a cone of half-angle `halfAngle` around unit w
/// (Fibonacci spiral in the cap; equal weights). k = 1 returns w itself.
std::vector<Vec3> coneDirections(const Vec3& w, double halfAngle, int k);

}  // namespace lpm
