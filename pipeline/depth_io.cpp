#include "pipeline/depth_io.hpp"

#include <algorithm>
#include <bit>
#include <cctype>
#include <cerrno>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <fstream>
#include <iterator>
#include <limits>
#include <sstream>
#include <stdexcept>
#include <vector>

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "base/system_error.hpp"
#include "pipeline/row_stripes.hpp"

namespace stereod {
namespace {

static_assert(std::endian::native == std::endian::little || std::endian::native == std::endian::big,
              "mixed-endian machines are not supported");
static_assert(sizeof(float) == 4 && sizeof(CloudPoint) == 4 * sizeof(float),
              "CloudPoint must be four packed floats");

constexpr float kInvalidDisparity = std::numeric_limits<float>::infinity();
// KITTI stores disparity * 256 in uint16 and reserves 0 for "invalid".
constexpr double kKittiScale = 256.0;
constexpr double kMillimetresPerMetre = 1000.0;

[[noreturn]] void ioError(const std::string& path, const std::string& what)
{
    throw std::runtime_error(path + ": " + what);
}

std::string errnoSuffix(int error)
{
    return error != 0 ? std::string(": ") + errnoText(error) : std::string();
}

std::string extensionOf(const std::string& path)
{
    const auto dot = path.rfind('.');
    const auto slash = path.rfind('/');
    if (dot == std::string::npos || (slash != std::string::npos && dot < slash))
        return {};
    std::string ext = path.substr(dot + 1);
    for (char& c : ext)
        c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
    return ext;
}

uint32_t byteSwap(uint32_t v)
{
    return ((v & 0xffu) << 24) | ((v & 0xff00u) << 8) | ((v >> 8) & 0xff00u) | (v >> 24);
}

// A float in little-endian byte order, whatever the host's.
float toLittleEndian(float value)
{
    if constexpr (std::endian::native == std::endian::little)
        return value;
    return std::bit_cast<float>(byteSwap(std::bit_cast<uint32_t>(value)));
}

void writeImage(const std::string& path, const cv::Mat& image)
{
    errno = 0;
    bool ok = false;
    try {
        ok = cv::imwrite(path, image);
    } catch (const cv::Exception& e) {
        ioError(path, std::string("cannot write image: ") + e.what());
    }
    if (!ok) {
        const int error = errno;
        ioError(path, "cannot write image" + errnoSuffix(error));
    }
}

cv::Mat readUint16Png(const std::string& path)
{
    errno = 0;
    cv::Mat image = cv::imread(path, cv::IMREAD_UNCHANGED);
    if (image.empty()) {
        const int error = errno;
        ioError(path, "cannot read image" + errnoSuffix(error));
    }
    if (image.type() != CV_16UC1)
        ioError(path, "expected a single-channel 16-bit PNG");
    return image;
}

void openForWriting(std::ofstream& out, const std::string& path)
{
    out.open(path, std::ios::binary | std::ios::trunc);
    if (!out) {
        const int error = errno;
        ioError(path, "cannot open for writing" + errnoSuffix(error));
    }
}

void finishWriting(std::ofstream& out, const std::string& path)
{
    out.flush();
    if (!out) {
        const int error = errno;
        ioError(path, "cannot write" + errnoSuffix(error));
    }
    out.close();
    if (!out) {
        const int error = errno;
        ioError(path, "cannot close" + errnoSuffix(error));
    }
}

// Portable float map, single channel ("Pf"): a text header "Pf\nW H\nSCALE\n", SCALE < 0
// meaning little-endian data, then W*H floats, rows from the BOTTOM of the image up.
void writePfm(const std::string& path, const cv::Mat& disparity)
{
    std::ofstream out;
    openForWriting(out, path);
    out << "Pf\n" << disparity.cols << ' ' << disparity.rows << "\n-1\n";
    std::vector<float> row(static_cast<size_t>(disparity.cols));
    for (int y = disparity.rows - 1; y >= 0; --y) {
        const float* src = disparity.ptr<float>(y);
        for (int x = 0; x < disparity.cols; ++x) {
            // NaN is also "invalid" on input; the file uses Middlebury's +inf only.
            const float v = std::isnan(src[x]) ? kInvalidDisparity : src[x];
            row[static_cast<size_t>(x)] = toLittleEndian(v);
        }
        out.write(reinterpret_cast<const char*>(row.data()),
                  static_cast<std::streamsize>(row.size() * sizeof(float)));
    }
    finishWriting(out, path);
}

cv::Mat readPfm(const std::string& path)
{
    std::ifstream in(path, std::ios::binary);
    if (!in) {
        const int error = errno;
        ioError(path, "cannot open" + errnoSuffix(error));
    }
    std::string magic;
    int width = 0;
    int height = 0;
    double scale = 0.0;
    in >> magic >> width >> height >> scale;
    if (!in)
        ioError(path, "not a PFM file: the header must be 'Pf', width, height, scale");
    if (magic == "PF")
        ioError(path, "a 3-channel PFM ('PF'); a disparity map is single-channel ('Pf')");
    if (magic != "Pf")
        ioError(path, "not a PFM file: starts with '" + magic + "', expected 'Pf'");
    if (width <= 0 || height <= 0 || width > (1 << 16) || height > (1 << 16))
        ioError(path,
                "implausible PFM size " + std::to_string(width) + "x" + std::to_string(height));
    if (scale == 0.0 || !std::isfinite(scale))
        ioError(path, "PFM scale must be non-zero (negative: little-endian)");
    // Exactly one whitespace character separates the header from the data.
    in.get();
    const bool big_endian = scale > 0.0;
    cv::Mat disparity(height, width, CV_32FC1);
    const std::streamsize row_bytes = static_cast<std::streamsize>(width) * 4;
    for (int y = height - 1; y >= 0; --y) {
        float* dst = disparity.ptr<float>(y);
        in.read(reinterpret_cast<char*>(dst), row_bytes);
        if (in.gcount() != row_bytes)
            ioError(path, "truncated PFM: the header announces " + std::to_string(width) + "x" +
                              std::to_string(height) + " floats");
        const bool swap = big_endian != (std::endian::native == std::endian::big);
        if (swap)
            for (int x = 0; x < width; ++x)
                dst[x] = std::bit_cast<float>(byteSwap(std::bit_cast<uint32_t>(dst[x])));
    }
    return disparity;
}

// value * scale, rounded, into uint16 (reusing `encoded`); 0 means invalid, so values that
// cannot be stored (not finite, <= 0, rounding to 0 or above 65535) become 0 rather than
// a wrong number.
void encodeUint16(const cv::Mat& values, double scale, cv::Mat& encoded)
{
    CV_Assert(values.type() == CV_32FC1);
    encoded.create(values.size(), CV_16UC1);
    for (int y = 0; y < values.rows; ++y) {
        const float* src = values.ptr<float>(y);
        uint16_t* dst = encoded.ptr<uint16_t>(y);
        for (int x = 0; x < values.cols; ++x) {
            const double scaled = std::isfinite(src[x]) ? std::round(src[x] * scale) : 0.0;
            dst[x] = (scaled >= 1.0 && scaled <= 65535.0) ? static_cast<uint16_t>(scaled) : 0;
        }
    }
}

void writeKittiPng(const std::string& path, const cv::Mat& disparity)
{
    // Disparities of 256 px and more do not fit: written as invalid.
    cv::Mat encoded;
    encodeUint16(disparity, kKittiScale, encoded);
    writeImage(path, encoded);
}

cv::Mat readKittiPng(const std::string& path)
{
    const cv::Mat encoded = readUint16Png(path);
    cv::Mat disparity(encoded.size(), CV_32FC1);
    for (int y = 0; y < encoded.rows; ++y) {
        const uint16_t* src = encoded.ptr<uint16_t>(y);
        float* dst = disparity.ptr<float>(y);
        for (int x = 0; x < encoded.cols; ++x)
            dst[x] = src[x] == 0 ? kInvalidDisparity : static_cast<float>(src[x] / kKittiScale);
    }
    return disparity;
}

void requireType(const cv::Mat& image, int type, const std::string& path, const char* what)
{
    if (image.empty() || image.type() != type)
        ioError(path, std::string("expected a non-empty ") + what);
}

} // namespace

void writeDisparity(const std::string& path, const cv::Mat& disparity)
{
    requireType(disparity, CV_32FC1, path, "CV_32FC1 disparity map");
    const std::string ext = extensionOf(path);
    if (ext == "pfm")
        writePfm(path, disparity);
    else if (ext == "png")
        writeKittiPng(path, disparity);
    else
        ioError(path, "unsupported disparity format '." + ext + "' (use .pfm or .png)");
}

cv::Mat readDisparity(const std::string& path)
{
    const std::string ext = extensionOf(path);
    if (ext == "pfm")
        return readPfm(path);
    if (ext == "png")
        return readKittiPng(path);
    ioError(path, "unsupported disparity format '." + ext + "' (use .pfm or .png)");
}

void depthToMillimetres(const cv::Mat& depth_m, cv::Mat& depth_mm)
{
    CV_Assert(depth_m.type() == CV_32FC1);
    depth_mm.create(depth_m.size(), CV_16UC1);
    // The service's hot path: no branch and no library call per pixel, so that the
    // compiler vectorises it. The arithmetic is encodeUint16's: the product of a float and
    // 1000 is exact in double, and floor(mm + 0.5) equals std::round(mm) for every
    // mm >= 0 it can produce; negative, NaN and infinite depths fail the range test.
    // Beyond 65.535 m (or rounding to 0 mm) a depth cannot be stored: 0, invalid, never
    // clipped.
    const auto toMillimetres = [](float z_m) -> uint16_t {
        const double rounded_up = static_cast<double>(z_m) * kMillimetresPerMetre + 0.5;
        const bool valid = rounded_up >= 1.0 && rounded_up < 65536.0;
        // Selected before the conversion, so that only in-range values are converted.
        return static_cast<uint16_t>(static_cast<int32_t>(valid ? rounded_up : 0.0));
    };
    // Blocks of a fixed length: GCC vectorises those at -O2 too (its cheapest cost model
    // takes no loop whose length it does not know).
    constexpr int kBlock = 64;
    const int width = depth_m.cols;
    // Rows in stripes over OpenCV's pool: the publisher's thread would otherwise convert
    // a frame alone while the pool's threads wait.
    forRowStripes(0, depth_m.rows, [&](int first, int end) {
        for (int y = first; y < end; ++y) {
            const float* z = depth_m.ptr<float>(y);
            uint16_t* mm = depth_mm.ptr<uint16_t>(y);
            int x = 0;
            for (; x + kBlock <= width; x += kBlock)
                for (int i = 0; i < kBlock; ++i)
                    mm[x + i] = toMillimetres(z[x + i]);
            for (; x < width; ++x)
                mm[x] = toMillimetres(z[x]);
        }
    });
}

void writeDepthPng(const std::string& path, const cv::Mat& depth_m)
{
    requireType(depth_m, CV_32FC1, path, "CV_32FC1 depth map");
    if (extensionOf(path) != "png")
        ioError(path, "a depth map is written as .png (uint16 millimetres)");
    cv::Mat depth_mm;
    depthToMillimetres(depth_m, depth_mm);
    writeImage(path, depth_mm);
}

void writeConfidencePng(const std::string& path, const cv::Mat& confidence)
{
    requireType(confidence, CV_8UC1, path, "CV_8UC1 confidence map");
    if (extensionOf(path) != "png")
        ioError(path, "a confidence map is written as .png (uint8, 0 = no disparity)");
    writeImage(path, confidence);
}

cv::Mat readDepthPng(const std::string& path)
{
    const cv::Mat depth_mm = readUint16Png(path);
    cv::Mat depth_m;
    depth_mm.convertTo(depth_m, CV_32FC1, 1.0 / kMillimetresPerMetre);
    return depth_m;
}

void writePly(const std::string& path, const std::vector<CloudPoint>& cloud,
              const std::vector<CloudColour>& colours)
{
    const bool coloured = !colours.empty();
    if (coloured && colours.size() != cloud.size())
        throw std::invalid_argument(path + ": " + std::to_string(colours.size()) +
                                    " colours for a cloud of " + std::to_string(cloud.size()) +
                                    " points");
    std::ofstream out;
    openForWriting(out, path);
    out << "ply\n"
        << "format binary_little_endian 1.0\n"
        << "comment stereod point cloud: metres, rectified left camera (x right, y down, "
           "z forward); intensity 0..255\n"
        << "element vertex " << cloud.size() << "\n"
        << "property float x\n"
        << "property float y\n"
        << "property float z\n"
        << "property float intensity\n";
    if (coloured)
        out << "property uchar red\n"
            << "property uchar green\n"
            << "property uchar blue\n";
    out << "end_header\n";
    if (!coloured && std::endian::native == std::endian::little) {
        out.write(reinterpret_cast<const char*>(cloud.data()),
                  static_cast<std::streamsize>(cloud.size() * sizeof(CloudPoint)));
    } else {
        for (std::size_t i = 0; i < cloud.size(); ++i) {
            const CloudPoint& p = cloud[i];
            const float v[4] = {toLittleEndian(p.x), toLittleEndian(p.y), toLittleEndian(p.z),
                                toLittleEndian(p.intensity)};
            out.write(reinterpret_cast<const char*>(v), sizeof(v));
            if (coloured) {
                const char rgb[3] = {static_cast<char>(colours[i].r),
                                     static_cast<char>(colours[i].g),
                                     static_cast<char>(colours[i].b)};
                out.write(rgb, sizeof(rgb));
            }
        }
    }
    finishWriting(out, path);
}

cv::Mat colorizeDepth(const cv::Mat& depth_m, double min_depth_m, double max_depth_m)
{
    CV_Assert(depth_m.type() == CV_32FC1);
    if (!(min_depth_m > 0.0 && max_depth_m > min_depth_m))
        throw std::invalid_argument("colorizeDepth: need 0 < min_depth_m < max_depth_m, got " +
                                    std::to_string(min_depth_m) + " and " +
                                    std::to_string(max_depth_m));
    // Inverse depth spreads the colours where a robot cares: up close.
    const double inv_far = 1.0 / max_depth_m;
    const double inv_near = 1.0 / min_depth_m;
    cv::Mat level(depth_m.size(), CV_8UC1);
    cv::Mat invalid(depth_m.size(), CV_8UC1);
    for (int y = 0; y < depth_m.rows; ++y) {
        const float* z = depth_m.ptr<float>(y);
        uint8_t* lv = level.ptr<uint8_t>(y);
        uint8_t* bad = invalid.ptr<uint8_t>(y);
        for (int x = 0; x < depth_m.cols; ++x) {
            const bool ok = z[x] > 0.0f && std::isfinite(z[x]);
            bad[x] = ok ? 0 : 255;
            const double t =
                ok ? std::clamp((1.0 / z[x] - inv_far) / (inv_near - inv_far), 0.0, 1.0) : 0.0;
            lv[x] = static_cast<uint8_t>(std::lround(t * 255.0));
        }
    }
    cv::Mat colour;
    // JET runs from blue (0, far) to red (255, near).
    cv::applyColorMap(level, colour, cv::COLORMAP_JET);
    colour.setTo(cv::Scalar::all(0), invalid);
    return colour;
}

void writeColorizedDepth(const std::string& path, const cv::Mat& depth_m, double min_depth_m,
                         double max_depth_m)
{
    writeImage(path, colorizeDepth(depth_m, min_depth_m, max_depth_m));
}

} // namespace stereod
