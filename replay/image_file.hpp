#pragma once
// Reading an image file of a recording without trusting it: a bounded read of a regular
// file, and the image's size and completeness from its header, before any decoding. A
// 389 KB PNG can declare 20000x20000 pixels (400 MB once decoded), a row of frames.csv
// can point at /dev/zero or a FIFO, and a truncated JPEG decodes into a grey-filled
// picture that passes for a frame; all of them are refused here, naming the file.
//
// Pure functions, no state: thread-safe.

#include <cstddef>
#include <cstdint>
#include <span>
#include <string>
#include <vector>

#include <opencv2/core/types.hpp>

namespace stereod {

enum class ImageFormat {
    Png,
    Jpeg,
    Other, // decoded without a look at the header first (BMP, TIFF, PNM, ...)
};

struct ImageHeader {
    ImageFormat format = ImageFormat::Other;
    cv::Size size;        // from the header; empty when unknown (Other, or unreadable)
    bool complete = true; // PNG ends with IEND, JPEG with its EOI marker
    bool colour = false;  // PNG of colour type RGB, RGBA or palette; JPEG of 3 or more components
    // An 8-bit colour PNG without a gAMA, sRGB, iCCP or cHRM chunk before its pixels: its
    // grey decode (libpng's rgb_to_gray, as OpenCV asks for it) is then a fixed integer
    // weighting of its decoded red, green and blue alone (pngGreyFromBgr()).
    bool grey_from_rgb = false;
    std::string problem; // a PNG or JPEG whose header cannot be read: why
};

// The format, size and completeness of the image in `bytes` (the whole file), from the
// PNG IHDR chunk or the JPEG SOFn segment, without decoding a pixel.
ImageHeader parseImageHeader(std::span<const uint8_t> bytes);

// Reads the whole of `path` into `bytes` (its capacity kept across calls), if it is a
// regular file of at most `max_bytes`; opened without blocking (a FIFO, a device, a
// directory are refused, not waited on). Returns 0, or an errno (ENOENT missing, EACCES,
// EINVAL not a regular file, EFBIG too large) with `reason` saying why in words.
int readImageFile(const std::string& path, std::size_t max_bytes, std::vector<uint8_t>& bytes,
                  std::string& reason);

} // namespace stereod
