#pragma once
// PNG and JPEG decoded with libpng and libjpeg(-turbo) themselves, set up as OpenCV's
// imdecode sets them up (the same transforms, so the same pixels), with what the libraries
// would print on their own (libpng's "libpng error: ...", libjpeg's "Corrupt JPEG data:
// ...") collected into a string instead of going to the process's stderr.
//
// Reentrant: each call has its own decoder state and touches no process-wide state (no
// fd, no lock); calls from several threads run side by side.
// Ownership: reads `bytes` during the call only; `out` is (re)allocated by the call.
// Units: pixels; 8-bit samples.

#include <cstdint>
#include <string>
#include <vector>

#include <opencv2/core/mat.hpp>

namespace stereod {

enum class CodecResult {
    Decoded,    // `out` holds the image
    Failed,     // the library refused the file; `printed` says why
    NotCovered, // a file these decoders leave to cv::imdecode (CMYK JPEG, EXIF orientation)
};

// Decodes a PNG (`bytes` starts with its signature) into `out`: CV_8UC1 when `colour` is
// false, else CV_8UC3 BGR, exactly what cv::imdecode(IMREAD_GRAYSCALE / IMREAD_COLOR)
// gives. `printed` gets libpng's messages, "libpng warning: ..." / "libpng error: ...",
// separated by ';'.
CodecResult decodePng(const std::vector<uint8_t>& bytes, bool colour, cv::Mat& out,
                      std::string& printed);

// The same for a JPEG, with libjpeg's messages (its first warning and its error, as
// libjpeg's own handlers would print them).
CodecResult decodeJpeg(const std::vector<uint8_t>& bytes, bool colour, cv::Mat& out,
                       std::string& printed);

} // namespace stereod
