#include "pipeline/rectifier.hpp"

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <stdexcept>
#include <string>

#include <opencv2/calib3d.hpp>
#include <opencv2/core/utility.hpp>
#include <opencv2/imgproc.hpp>

#include "pipeline/cv_conversions.hpp"
#include "pipeline/resample/remap_kernels.hpp"
#include "pipeline/row_stripes.hpp"

// Why the remap is ours and not cv::remap: the service promises no heap allocation per
// frame in steady state, and OpenCV 4.6's cv::remap creates two temporary Mats for every
// stripe of every call (its RemapInvoker buffers the map tiles), 20 to 56 allocations per
// frame at 640x480 to 1280x720. The maps themselves are computed once by OpenCV; only the
// per-frame resampling is done here, with OpenCV's fixed-point arithmetic so that the
// output is the same. Rows are still shared out with cv::parallel_for_ (forRowStripes(),
// row_stripes.hpp: a ParallelLoopBody rather than a std::function, which may need the
// heap): with the TBB backend of Debian's OpenCV it allocates nothing per call once its
// workers run
// (counted with the benchmark's operator new and cv::Mat counters, and with a counting
// malloc); tests/pipeline/hot_path_alloc_test.cpp keeps the first two at 0.

namespace stereod {
namespace {

// Sub-pixel positions as cv::initUndistortRectifyMap stores them: INTER_BITS = 5, so 32
// steps per pixel in x and in y, and map_frac = fy * 32 + fx.
constexpr int kInterBits = resample::kInterBits;
constexpr int kInterTabSize = 1 << kInterBits;
// Bilinear weights in fixed point, as OpenCV's remap: the four neighbours get
// (32 - fx)(32 - fy), fx (32 - fy), (32 - fx) fy and fx fy, exact integers summing to
// 1 << 10. OpenCV scales the same weights to 1 << 15 (INTER_REMAP_COEF_BITS) and rounds
// with (sum + (1 << 14)) >> 15, which equals (sum + (1 << 9)) >> 10 on weights 32 times
// smaller, so the result is bit-identical to cv::remap. The weighted sum is formed in
// two steps, along x then along y:
//   top = tl * 32 + (tr - tl) * fx        (0..8160, fits int16)
//   out = (top * (32 - fy) + bottom * fy + 512) >> 10
// which is the same integer as the four-term sum, with three multiplications. The grey
// image's rows go through the remap kernels (pipeline/resample/remap_kernels.hpp).
constexpr int kWeightBits = 2 * kInterBits;
constexpr int kRounding = 1 << (kWeightBits - 1);

resample::RemapSource sourceOf(const cv::Mat& src)
{
    return {src.data, src.step[0], src.cols, src.rows};
}

// Output pixels whose neighbourhoods are found per pass when no offsets were made
// beforehand (a source other than the calibrated camera's continuous grey frame).
constexpr int kChunk = 256;

// Output rows [rows.start, rows.end) of a grey image. Holds references only: it lives on
// the caller's stack for one call, and forRowStripes() takes it by reference.
class RemapRows {
  public:
    // offsets: remapOffsets() of map_xy for src's size and row step, or null.
    RemapRows(const cv::Mat& src, const cv::Mat& map_xy, const cv::Mat& map_frac,
              const cv::Mat* offsets, cv::Mat& out)
        : src_(sourceOf(src)), map_xy_(map_xy), map_frac_(map_frac), offsets_(offsets), out_(out),
          kernels_(resample::simdRemapKernels())
    {
    }

    void operator()(const cv::Range& rows) const
    {
        int32_t offsets[kChunk];
        for (int y = rows.start; y < rows.end; ++y) {
            const int16_t* xy = map_xy_.ptr<int16_t>(y);
            const uint16_t* frac = map_frac_.ptr<uint16_t>(y);
            uint8_t* dst = out_.ptr<uint8_t>(y);
            if (offsets_ != nullptr) {
                kernels_.remap_row(src_, offsets_->ptr<int32_t>(y), xy, frac, out_.cols, dst);
                continue;
            }
            for (int x0 = 0; x0 < out_.cols; x0 += kChunk) {
                const int n = std::min(kChunk, out_.cols - x0);
                for (int i = 0; i < n; ++i)
                    offsets[i] =
                        resample::neighbourhoodOffset(xy[2 * (x0 + i)], xy[2 * (x0 + i) + 1], src_);
                kernels_.remap_row(src_, offsets, xy + 2 * x0, frac + x0, n, dst + x0);
            }
        }
    }

  private:
    const resample::RemapSource src_;
    const cv::Mat& map_xy_;
    const cv::Mat& map_frac_;
    const cv::Mat* offsets_;
    cv::Mat& out_;
    const resample::RemapKernels& kernels_;
};

// The colour image (CV_8UC3, three interleaved channels) through the same maps and the
// same fixed-point arithmetic, channel by channel: bit-identical to cv::remap too. A
// plain per-pixel loop: the colour left is resampled for the outputs only (the matcher
// works on grey), and at 640x480 this costs a few ms (bench/README.md, "Colour").
class RemapRowsColour {
  public:
    RemapRowsColour(const cv::Mat& src, const cv::Mat& map_xy, const cv::Mat& map_frac,
                    cv::Mat& out)
        : src_(src), map_xy_(map_xy), map_frac_(map_frac), out_(out)
    {
    }

    void operator()(const cv::Range& rows) const
    {
        const auto interior_cols = static_cast<unsigned>(src_.cols - 1);
        const auto interior_rows = static_cast<unsigned>(src_.rows - 1);
        const size_t step = src_.step[0];
        for (int y = rows.start; y < rows.end; ++y) {
            const int16_t* xy = map_xy_.ptr<int16_t>(y);
            const uint16_t* frac = map_frac_.ptr<uint16_t>(y);
            uint8_t* dst = out_.ptr<uint8_t>(y);
            for (int x = 0; x < out_.cols; ++x) {
                const int sx = xy[2 * x];
                const int sy = xy[2 * x + 1];
                const int fx = frac[x] & (kInterTabSize - 1);
                const int fy = (frac[x] >> kInterBits) & (kInterTabSize - 1);
                uint8_t tl[3], tr[3], bl[3], br[3];
                if (static_cast<unsigned>(sx) < interior_cols &&
                    static_cast<unsigned>(sy) < interior_rows) {
                    const uint8_t* t = src_.data + static_cast<size_t>(sy) * step + 3 * sx;
                    const uint8_t* b = t + step;
                    for (int c = 0; c < 3; ++c) {
                        tl[c] = t[c];
                        tr[c] = t[3 + c];
                        bl[c] = b[c];
                        br[c] = b[3 + c];
                    }
                } else {
                    pixel(sx, sy, tl);
                    pixel(sx + 1, sy, tr);
                    pixel(sx, sy + 1, bl);
                    pixel(sx + 1, sy + 1, br);
                }
                for (int c = 0; c < 3; ++c) {
                    const int t = (tl[c] << kInterBits) + (tr[c] - tl[c]) * fx;
                    const int b = (bl[c] << kInterBits) + (br[c] - bl[c]) * fx;
                    dst[3 * x + c] = static_cast<uint8_t>(
                        (t * (kInterTabSize - fy) + b * fy + kRounding) >> kWeightBits);
                }
            }
        }
    }

  private:
    // A neighbour outside the source counts as 0 (BORDER_CONSTANT).
    void pixel(int x, int y, uint8_t* bgr) const
    {
        const bool inside = x >= 0 && x < src_.cols && y >= 0 && y < src_.rows;
        for (int c = 0; c < 3; ++c)
            bgr[c] = inside ? src_.ptr<uint8_t>(y)[3 * x + c] : uint8_t{0};
    }

    const cv::Mat& src_;
    const cv::Mat& map_xy_;
    const cv::Mat& map_frac_;
    cv::Mat& out_;
};

void requireArgument(bool ok, const char* what)
{
    if (!ok)
        throw std::invalid_argument(std::string("remapBilinear: ") + what);
}

bool overlaps(const cv::Mat& a, const cv::Mat& b)
{
    return a.datastart < b.dataend && b.datastart < a.dataend;
}

// The checks of remapBilinear(); sizes `out`.
void prepareRemap(const cv::Mat& src, const cv::Mat& map_xy, const cv::Mat& map_frac, cv::Mat& out)
{
    requireArgument(!src.empty() && (src.type() == CV_8UC1 || src.type() == CV_8UC3),
                    "the source must be a non-empty CV_8UC1 or CV_8UC3 image");
    requireArgument(!map_xy.empty() && map_xy.type() == CV_16SC2,
                    "map_xy must be a non-empty CV_16SC2 map");
    requireArgument(map_frac.type() == CV_16UC1 && map_frac.size() == map_xy.size(),
                    "map_frac must be CV_16UC1 with map_xy's size");
    out.create(map_xy.size(), src.type());
    requireArgument(!overlaps(src, out), "the output must not share the source's buffer");
}

// Whether the Rectifier's offsets (made for a continuous grey image of the maps' size)
// serve this source.
bool offsetsFit(const cv::Mat& offsets, const cv::Mat& src)
{
    return !offsets.empty() && src.type() == CV_8UC1 && src.size() == offsets.size() &&
           src.step[0] == static_cast<size_t>(src.cols);
}

// remapBilinear(), through `offsets` (remapOffsets() for this grey source) when given.
void remap(const cv::Mat& src, const cv::Mat& map_xy, const cv::Mat& map_frac,
           const cv::Mat* offsets, cv::Mat& out)
{
    prepareRemap(src, map_xy, map_frac, out);
    if (src.type() == CV_8UC3) {
        const RemapRowsColour body(src, map_xy, map_frac, out);
        forRowStripes(0, out.rows, [&](int first, int end) { body(cv::Range(first, end)); });
        return;
    }
    const RemapRows body(src, map_xy, map_frac, offsets, out);
    forRowStripes(0, out.rows, [&](int first, int end) { body(cv::Range(first, end)); });
}

} // namespace

void remapBilinear(const cv::Mat& src, const cv::Mat& map_xy, const cv::Mat& map_frac, cv::Mat& out)
{
    remap(src, map_xy, map_frac, nullptr, out);
}

cv::Mat remapOffsets(const cv::Mat& map_xy, cv::Size src_size, size_t src_step)
{
    requireArgument(!map_xy.empty() && map_xy.type() == CV_16SC2,
                    "map_xy must be a non-empty CV_16SC2 map");
    requireArgument(static_cast<size_t>(src_size.height) * src_step < (size_t{1} << 31),
                    "the source is too large for 32-bit offsets");
    const resample::RemapSource src{nullptr, src_step, src_size.width, src_size.height};
    cv::Mat offsets(map_xy.size(), CV_32SC1);
    for (int y = 0; y < map_xy.rows; ++y) {
        const int16_t* xy = map_xy.ptr<int16_t>(y);
        int32_t* offset = offsets.ptr<int32_t>(y);
        for (int x = 0; x < map_xy.cols; ++x)
            offset[x] = resample::neighbourhoodOffset(xy[2 * x], xy[2 * x + 1], src);
    }
    return offsets;
}

Rectifier::Rectifier(const StereoCalibration& calibration)
{
    if (calibration.kind != StereoCalibration::Kind::Full)
        return;
    const cv::Size size = toCv(calibration.rectified.image_size);
    cv::initUndistortRectifyMap(calibration.left.camera_matrix, calibration.left.distortion,
                                calibration.R1, calibration.P1, size, CV_16SC2, left_.xy,
                                left_.frac);
    cv::initUndistortRectifyMap(calibration.right.camera_matrix, calibration.right.distortion,
                                calibration.R2, calibration.P2, size, CV_16SC2, right_.xy,
                                right_.frac);
    // A camera's grey frame is a continuous image of the calibrated size.
    left_.offsets = remapOffsets(left_.xy, size, static_cast<size_t>(size.width));
    right_.offsets = remapOffsets(right_.xy, size, static_cast<size_t>(size.width));
}

void Rectifier::rectifyLeft(const cv::Mat& raw, cv::Mat& out) const
{
    apply(raw, left_, out);
}

void Rectifier::rectifyRight(const cv::Mat& raw, cv::Mat& out) const
{
    apply(raw, right_, out);
}

void Rectifier::rectifyPair(const cv::Mat& left_raw, const cv::Mat& right_raw, cv::Mat& left_out,
                            cv::Mat& right_out) const
{
    if (!offsetsFit(left_.offsets, left_raw) || !offsetsFit(right_.offsets, right_raw)) {
        rectifyLeft(left_raw, left_out);
        rectifyRight(right_raw, right_out);
        return;
    }
    prepareRemap(left_raw, left_.xy, left_.frac, left_out);
    prepareRemap(right_raw, right_.xy, right_.frac, right_out);
    requireArgument(!overlaps(left_raw, right_out) && !overlaps(right_raw, left_out),
                    "an output must not share an input's buffer");
    // Both images' rows in one call: one wake-up of the pool's threads, not two.
    const RemapRows left(left_raw, left_.xy, left_.frac, &left_.offsets, left_out);
    const RemapRows right(right_raw, right_.xy, right_.frac, &right_.offsets, right_out);
    const int rows = left_out.rows;
    forRowStripes(0, 2 * rows, [&](int first, int end) {
        if (first < rows)
            left(cv::Range(first, std::min(end, rows)));
        if (end > rows)
            right(cv::Range(std::max(first, rows) - rows, end - rows));
    });
}

void Rectifier::apply(const cv::Mat& raw, const Maps& maps, cv::Mat& out)
{
    if (maps.xy.empty()) {
        // copyTo() reuses `out` when size and type match.
        raw.copyTo(out);
        return;
    }
    remap(raw, maps.xy, maps.frac, offsetsFit(maps.offsets, raw) ? &maps.offsets : nullptr, out);
}

} // namespace stereod
