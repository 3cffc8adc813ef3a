// Pooled scratch blocks on huge pages (core/scratch_pool.h).
#include "core/scratch_pool.h"

#include <algorithm>
#include <cstdlib>
#include <mutex>
#include <new>
#include <vector>

#include "core/malloc_policy.h"

namespace lpm {

namespace {

constexpr std::size_t kHuge = std::size_t(2) << 20;
constexpr std::size_t kPooledFrom = std::size_t(1) << 20;  // bytes

struct Block {
    float* p;
    std::size_t floats;
};

struct Pool {
    std::mutex m;
    std::vector<Block> free;  // in order of return; searched for the best fit
    std::size_t bytes = 0;    // in use and free
};

Pool& pool() {
    static Pool* p = new Pool;  // never destroyed: blocks may come back during static destruction
    return *p;
}

}  // namespace

ScratchBlock::ScratchBlock(std::size_t floats) {
    const std::size_t want = std::max<std::size_t>(floats, 1) * sizeof(float);
    if (want < kPooledFrom) {
        p_ = new float[want / sizeof(float)];
        cap_ = want / sizeof(float);
        return;
    }
    pooled_ = true;
    Pool& pl = pool();
    std::vector<Block> stale;
    {
        std::lock_guard<std::mutex> lock(pl.m);
        auto best = pl.free.end();
        for (auto it = pl.free.begin(); it != pl.free.end(); ++it)
            if (it->floats * sizeof(float) >= want && (best == pl.free.end() || it->floats < best->floats)) best = it;
        if (best != pl.free.end()) {
            p_ = best->p;
            cap_ = best->floats;
            pl.free.erase(best);
            return;
        }
        stale.swap(pl.free);  // none fits: let the smaller ones go before growing
        for (const Block& b : stale) pl.bytes -= b.floats * sizeof(float);
    }
    for (const Block& b : stale) std::free(b.p);
    const std::size_t bytes = (want + kHuge - 1) / kHuge * kHuge;
    void* p = std::aligned_alloc(kHuge, bytes);
    if (!p) throw std::bad_alloc();
    adviseHugePages(p, bytes);
    p_ = static_cast<float*>(p);
    cap_ = bytes / sizeof(float);
    std::lock_guard<std::mutex> lock(pl.m);
    pl.bytes += bytes;
}

ScratchBlock::~ScratchBlock() {
    if (!pooled_) {
        delete[] p_;
        return;
    }
    Pool& pl = pool();
    std::lock_guard<std::mutex> lock(pl.m);
    pl.free.push_back({p_, cap_});
}

std::size_t releaseScratchPool() {
    Pool& pl = pool();
    std::lock_guard<std::mutex> lock(pl.m);
    std::size_t freed = 0;
    for (const Block& b : pl.free) {
        std::free(b.p);
        freed += b.floats * sizeof(float);
    }
    pl.free.clear();
    pl.bytes -= freed;
    return freed;
}

std::size_t scratchPoolBytes() {
    Pool& pl = pool();
    std::lock_guard<std::mutex> lock(pl.m);
    return pl.bytes;
}

}  // namespace lpm
