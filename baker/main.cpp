// lpmbake entry point: everything lives in the lpm_baker library (baker/cli.cpp).
#include "baker/options.h"

int main(int argc, char** argv) { return lpm::runCli(argc, argv); }
