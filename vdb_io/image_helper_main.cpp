// lpmbake-image: the process that reads and writes image files for lpmbake with
// OpenImageIO (image_helper.h). Not meant to be run by hand:
//   lpmbake-image decode PATH                   stdout: the decoded image (image_protocol.h)
//   lpmbake-image encode WRITE_PATH SHOWN_PATH  stdin: the image to encode
// On failure it prints one line to stderr and exits 1.
#include <unistd.h>

#include <cstring>
#include <iostream>
#include <string>

#include "vdb_io/image_codec.h"
#include "vdb_io/image_protocol.h"

int main(int argc, char** argv) {
    try {
        if (argc == 3 && std::strcmp(argv[1], "decode") == 0) {
            lpm::writeDecodedImage(STDOUT_FILENO, lpm::decodeImageFile(argv[2]));
            return 0;
        }
        if (argc == 4 && std::strcmp(argv[1], "encode") == 0) {
            lpm::encodeImageFile(argv[2], argv[3], lpm::readImageToEncode(STDIN_FILENO));
            return 0;
        }
        std::cerr << "usage: lpmbake-image decode PATH | encode WRITE_PATH SHOWN_PATH (run by lpmbake)\n";
    } catch (const std::exception& e) {
        std::cerr << e.what() << "\n";
    }
    return 1;
}
