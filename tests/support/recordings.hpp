#pragma once
// Recordings made at test time from real images (crops of the Middlebury Tsukuba pair),
// written into a test::TempDir (tests/support/temp_dir.hpp) that removes itself.

#include <cstdint>
#include <string>
#include <vector>

#include <opencv2/core/mat.hpp>

#include "tests/support/temp_dir.hpp"

namespace stereod::test {

struct TestPair {
    cv::Mat left; // CV_8UC1
    cv::Mat right;
    int64_t left_stamp_ns = 0;
    int64_t right_stamp_ns = 0;
};

// `count` distinct pairs of `size` (at most 16), cut from Tsukuba (im3 left, im4 right)
// at shifting offsets, in grayscale. Fails the calling test when the data are missing.
std::vector<TestPair> tsukubaPairs(int count, cv::Size size = cv::Size(96, 72));

// Stamps pair k at first_ns + k * spacing_ns, its right frame skew_ns(k) later.
void stampPairs(std::vector<TestPair>& pairs, int64_t first_ns, int64_t spacing_ns);

// Writes the pairs as a recording in `dir` with RecordingWriter.
void writeRecording(const std::string& dir, const std::vector<TestPair>& pairs,
                    const std::string& calibration_path = {});

// The recorded right-minus-left skew of pair k used by stampPairs(): a few hundred
// microseconds, either sign.
int64_t testSkewNs(int k);

// The pixels of an 8-bit image, row after row, in base64: how the interop scripts
// (tests/mcap_interop) print image data.
std::string base64(const cv::Mat& image);

// Pixel-for-pixel equality of two single-channel 8-bit images.
bool samePixels(const cv::Mat& a, const cv::Mat& b);

// Overwrites `path` with bytes that are no image at all.
void writeGarbage(const std::string& path, std::size_t bytes = 2048);

// Writes a valid grey 8-bit PNG of `size`, all black: a few hundred KB on disk for
// 20000x20000 (400 MB once decoded), written row by row without holding the image.
void writeDecompressionBomb(const std::string& path, cv::Size size);

// The bytes of `image` encoded as `extension` (".png", ".jpg").
std::vector<uint8_t> encode(const cv::Mat& image, const std::string& extension);

// Writes `bytes` to `path`, replacing it.
void writeBytes(const std::string& path, const std::vector<uint8_t>& bytes);

} // namespace stereod::test
