#include "replay/image_file.hpp"

#include <algorithm>
#include <cerrno>
#include <system_error>

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include "base/system_error.hpp"
#include "base/unique_fd.hpp"

namespace stereod {

namespace {

constexpr uint8_t kPngSignature[8] = {0x89, 'P', 'N', 'G', '\r', '\n', 0x1a, '\n'};
// Bytes a JPEG may carry after its EOI marker (padding some cameras and tools append).
constexpr std::size_t kJpegTrailerSlack = 64;

uint32_t bigEndian32(std::span<const uint8_t> bytes, std::size_t at)
{
    return (uint32_t{bytes[at]} << 24) | (uint32_t{bytes[at + 1]} << 16) |
           (uint32_t{bytes[at + 2]} << 8) | uint32_t{bytes[at + 3]};
}

uint32_t bigEndian16(std::span<const uint8_t> bytes, std::size_t at)
{
    return (uint32_t{bytes[at]} << 8) | uint32_t{bytes[at + 1]};
}

cv::Size boundedSize(uint32_t width, uint32_t height)
{
    // Beyond int: no image we could take; report it as the largest size, which no
    // expected size matches.
    constexpr uint32_t kMax = 1u << 30;
    return cv::Size(static_cast<int>(std::min(width, kMax)),
                    static_cast<int>(std::min(height, kMax)));
}

// Whether a gAMA, sRGB, iCCP or cHRM chunk comes before the PNG's first IDAT. Chunks are
// walked by their declared lengths within `bytes`; a walk that leaves the file says yes,
// the careful answer.
bool hasColourSpaceChunk(std::span<const uint8_t> bytes)
{
    const auto is = [&bytes](std::size_t at, const char* type) {
        return std::equal(type, type + 4, bytes.begin() + static_cast<std::ptrdiff_t>(at));
    };
    std::size_t at = 8; // after the signature: length (4), type (4), data, CRC (4)
    while (at + 8 <= bytes.size()) {
        const std::size_t type = at + 4;
        if (is(type, "IDAT"))
            return false;
        if (is(type, "gAMA") || is(type, "sRGB") || is(type, "iCCP") || is(type, "cHRM"))
            return true;
        at = type + 4 + std::size_t{bigEndian32(bytes, at)} + 4;
    }
    return true;
}

ImageHeader parsePng(std::span<const uint8_t> bytes)
{
    ImageHeader header;
    header.format = ImageFormat::Png;
    // Signature (8), IHDR length (4), "IHDR" (4), width (4), height (4).
    if (bytes.size() < 24 || bytes[12] != 'I' || bytes[13] != 'H' || bytes[14] != 'D' ||
        bytes[15] != 'R') {
        header.problem = "a PNG without its IHDR header";
        return header;
    }
    header.size = boundedSize(bigEndian32(bytes, 16), bigEndian32(bytes, 20));
    // Colour type (after the bit depth): 2 RGB, 3 palette, 6 RGB with alpha; 0 and 4 grey.
    header.colour = bytes.size() > 25 && (bytes[25] == 2 || bytes[25] == 3 || bytes[25] == 6);
    // libpng turns RGB to grey with gamma tables when the file names a gamma (gAMA, or
    // sRGB and an ICC profile that imply one), and 16-bit samples before they are cut to
    // 8: only without those is its grey a function of the 8-bit RGB the colour decode
    // gives. The chunks that matter come before the first IDAT.
    header.grey_from_rgb = header.colour && bytes[24] == 8 && !hasColourSpaceChunk(bytes);
    // The last chunk is IEND: length 0, "IEND", CRC.
    const std::size_t n = bytes.size();
    header.complete = n >= 24 + 12 && bytes[n - 8] == 'I' && bytes[n - 7] == 'E' &&
                      bytes[n - 6] == 'N' && bytes[n - 5] == 'D';
    return header;
}

ImageHeader parseJpeg(std::span<const uint8_t> bytes)
{
    ImageHeader header;
    header.format = ImageFormat::Jpeg;
    std::size_t at = 2; // after SOI
    while (at + 4 <= bytes.size()) {
        if (bytes[at] != 0xFF) {
            header.problem = "a JPEG whose segments do not follow each other";
            return header;
        }
        const uint8_t marker = bytes[at + 1];
        if (marker == 0xFF) { // fill byte
            ++at;
            continue;
        }
        // Markers without a length: TEM, RSTn.
        if (marker == 0x01 || (marker >= 0xD0 && marker <= 0xD7)) {
            at += 2;
            continue;
        }
        const std::size_t length = bigEndian16(bytes, at + 2);
        // SOF0..SOF15, except DHT (C4), JPG (C8) and DAC (CC).
        const bool frame =
            marker >= 0xC0 && marker <= 0xCF && marker != 0xC4 && marker != 0xC8 && marker != 0xCC;
        if (frame) {
            if (length < 7 || at + 9 > bytes.size()) {
                header.problem = "a JPEG whose frame header is cut short";
                return header;
            }
            header.size = boundedSize(bigEndian16(bytes, at + 7), bigEndian16(bytes, at + 5));
            // Components after the width: 1 grey, 3 YCbCr (or RGB), 4 CMYK.
            header.colour = at + 9 < bytes.size() && bytes[at + 9] >= 3;
            break;
        }
        if (marker == 0xDA || marker == 0xD9 || length < 2) {
            header.problem = "a JPEG without a frame header before its data";
            return header;
        }
        at += 2 + length;
    }
    if (header.size.empty() && header.problem.empty())
        header.problem = "a JPEG without a frame header";
    // The last marker is EOI (FF D9), give or take some padding. (In the entropy-coded
    // data an FF is always followed by 00 or a restart marker, never by D9.)
    const std::size_t n = bytes.size();
    const std::size_t from = n > kJpegTrailerSlack + 2 ? n - kJpegTrailerSlack - 2 : 0;
    header.complete = false;
    for (std::size_t i = from; i + 1 < n && !header.complete; ++i)
        header.complete = bytes[i] == 0xFF && bytes[i + 1] == 0xD9;
    return header;
}

} // namespace

ImageHeader parseImageHeader(std::span<const uint8_t> bytes)
{
    if (bytes.size() >= 8 &&
        std::equal(std::begin(kPngSignature), std::end(kPngSignature), bytes.begin()))
        return parsePng(bytes);
    if (bytes.size() >= 3 && bytes[0] == 0xFF && bytes[1] == 0xD8 && bytes[2] == 0xFF)
        return parseJpeg(bytes);
    return ImageHeader{};
}

int readImageFile(const std::string& path, std::size_t max_bytes, std::vector<uint8_t>& bytes,
                  std::string& reason)
{
    bytes.clear();
    const auto fail = [&](int code, std::string why) {
        reason = std::move(why);
        return code;
    };
    // O_NONBLOCK: opening a FIFO nobody writes must not wait.
    const UniqueFd file(::open(path.c_str(), O_RDONLY | O_CLOEXEC | O_NONBLOCK | O_NOCTTY));
    const int fd = file.get();
    if (!file) {
        const int code = errno;
        return fail(code,
                    code == ENOENT ? std::string("missing") : "cannot be read: " + errnoText(code));
    }
    struct stat info {};
    int code = 0;
    if (::fstat(fd, &info) != 0) {
        code = errno;
        reason = "cannot be read: " + errnoText(code);
    } else if (!S_ISREG(info.st_mode)) {
        code = EINVAL;
        reason = "is not a regular file (a device, a FIFO or a directory)";
    } else if (static_cast<uint64_t>(info.st_size) > max_bytes) {
        code = EFBIG;
        reason = "is " + std::to_string(info.st_size) + " bytes, more than the " +
                 std::to_string(max_bytes) + " an image may have";
    } else {
        // The file may change under us: never read more than max_bytes + 1.
        bytes.resize(static_cast<std::size_t>(info.st_size) + 1);
        std::size_t got = 0;
        while (got < bytes.size()) {
            const ssize_t n = ::read(fd, bytes.data() + got, bytes.size() - got);
            if (n < 0 && errno == EINTR)
                continue;
            if (n < 0) {
                code = errno;
                reason = "cannot be read: " + errnoText(code);
                break;
            }
            if (n == 0)
                break;
            got += static_cast<std::size_t>(n);
        }
        bytes.resize(code == 0 ? std::min(got, max_bytes) : 0);
        if (code == 0 && got > max_bytes) {
            code = EFBIG;
            reason = "grew beyond the " + std::to_string(max_bytes) + " bytes an image may have";
            bytes.clear();
        }
    }
    return code;
}

} // namespace stereod
