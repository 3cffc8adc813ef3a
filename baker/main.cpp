// lpmbake entry point: everything lives in the lpm_baker library (baker/cli.cpp).
#include "baker/options.h"
#include "core/malloc_policy.h"

int main(int argc, char** argv) {
    lpm::keepFreedBuffersForReuse();
    return lpm::runCli(argc, argv);
}
