// Constant-free renderer grids (renderer_grids.h).
#include "vdb_io/renderer_grids.h"

namespace lpm {

RendererGrids makeRendererGrids(const openvdb::FloatGrid& density, const openvdb::Vec3SGrid& scatter,
                                const openvdb::Vec3SGrid* emission, double densityScale, const RGB& albedo) {
    RendererGrids r;
    r.extinction = openvdb::FloatGrid::create(0.f);
    r.extinction->setTransform(density.transform().copy());
    r.extinction->tree().topologyUnion(density.tree());
    r.extinction->tree().voxelizeActiveTiles();
    r.source = openvdb::Vec3SGrid::create(openvdb::Vec3s(0.f));
    r.source->setTransform(density.transform().copy());
    r.source->tree().topologyUnion(r.extinction->tree());

    auto densityAt = density.getConstAccessor();
    auto scatterAt = scatter.getConstAccessor();
    std::unique_ptr<openvdb::Vec3SGrid::ConstAccessor> emissionAt;
    if (emission) emissionAt = std::make_unique<openvdb::Vec3SGrid::ConstAccessor>(emission->getConstAccessor());
    auto sourceAt = r.source->getAccessor();
    for (auto it = r.extinction->beginValueOn(); it; ++it) {
        const openvdb::Coord c = it.getCoord();
        const double sigmaT = double(densityAt.getValue(c)) * densityScale;
        it.setValue(float(sigmaT));
        const openvdb::Vec3s S = scatterAt.getValue(c);
        const openvdb::Vec3s Le = emissionAt ? emissionAt->getValue(c) : openvdb::Vec3s(0.f);
        openvdb::Vec3s src;
        for (int ch = 0; ch < 3; ++ch) src[ch] = float(sigmaT * (albedo[ch] * S[ch] + (1.0 - albedo[ch]) * Le[ch]));
        sourceAt.setValueOn(c, src);
    }
    r.extinction->setName("extinction");
    r.extinction->setGridClass(openvdb::GRID_FOG_VOLUME);
    r.extinction->insertMeta("lpm:description", openvdb::StringMetadata("sigma_t per world unit"));
    r.source->setName("source");
    r.source->setGridClass(openvdb::GRID_FOG_VOLUME);
    r.source->setVectorType(openvdb::VEC_INVARIANT);
    r.source->insertMeta("lpm:description",
                         openvdb::StringMetadata("sigma_s * scatter + sigma_a * L_e: emission per unit length"));
    return r;
}

}  // namespace lpm
