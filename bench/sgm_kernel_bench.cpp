// sgm_kernel_bench: what each census-sgm kernel costs per pixel of a row, by the number of
// disparity lanes it searches, on one core: the cost row, the forward paths (the path from
// above and the one along the row), and the winners (the backward path, the sums, the
// winner and the right view). Fitting the times over 32 to 256 lanes splits each kernel
// into what a pixel costs whatever its range and what each vector of 32 lanes adds
// (bench/README.md); with spans, what the guided search's narrow spans cost.
//
// The rows are a real pair's (aloe, OpenCV's samples), resized as the benchmark's frames,
// their census made by the kernels themselves. One row is run over and over: its blocks
// stay in the caches as a band's rows do in the matcher.

#include <cstdint>
#include <string>
#include <vector>

#include <benchmark/benchmark.h>
#include <opencv2/core.hpp>

#include "bench/bench_data.hpp"
#include "pipeline/sgm/sgm_kernels.hpp"

namespace stereod::bench {
namespace {

using sgm::kLaneAlign;

constexpr int kCensusWidth = 11; // census-sgm's defaults: 32 bits, four planes
constexpr int kCensusHeight = 3;
constexpr int kPlanes = 4;
constexpr uint8_t kP1 = 16;
constexpr uint8_t kCostInvalid = 32;

// One row of census planes of both views of aloe at `width` (the benchmark's frame sizes:
// 640x480 or 1280x720), its middle row, with the right row reversed and the margins
// cost_row() reads (sgm_kernels.hpp).
class CensusRow {
  public:
    CensusRow(int width, int lanes)
    {
        const int height = width == 640 ? 480 : 720;
        const ImagePair pair = loadScene(scenes().front(), cv::Size(width, height));
        const int y = height / 2;
        const int rx = kCensusWidth / 2, ry = kCensusHeight / 2;
        const int margin = lanes + kLaneAlign + 1;
        for (int p = 0; p < kPlanes; ++p) {
            left_[p].assign(static_cast<size_t>(width), 0);
            right_[p].assign(static_cast<size_t>(width), 0);
            reversed_[p].assign(static_cast<size_t>(width + 2 * margin), 0);
        }
        const sgm::SgmKernels& k = sgm::simdKernels();
        for (int view = 0; view < 2; ++view) {
            cv::Mat padded;
            cv::copyMakeBorder(view == 0 ? pair.left : pair.right, padded, ry, ry, rx, rx,
                               cv::BORDER_REPLICATE);
            uint8_t* planes[kPlanes];
            for (int p = 0; p < kPlanes; ++p)
                planes[p] = view == 0 ? left_[p].data() : right_[p].data();
            k.census_row(padded.ptr<uint8_t>(y + ry) + rx, padded.step, width, kCensusWidth,
                         kCensusHeight, planes);
        }
        for (int p = 0; p < kPlanes; ++p) {
            for (int j = 0; j < width; ++j)
                reversed_[p][static_cast<size_t>(margin + j)] =
                    right_[p][static_cast<size_t>(width - 1 - j)];
            left_ptr_[p] = left_[p].data();
            right_ptr_[p] = right_[p].data();
            reversed_ptr_[p] = reversed_[p].data() + margin;
        }
        rows_ = sgm::CensusRows{left_ptr_, right_ptr_, reversed_ptr_, kPlanes};
    }
    const sgm::CensusRows& rows() const { return rows_; }

  private:
    std::vector<uint8_t> left_[kPlanes], right_[kPlanes], reversed_[kPlanes];
    const uint8_t* left_ptr_[kPlanes] = {};
    const uint8_t* right_ptr_[kPlanes] = {};
    const uint8_t* reversed_ptr_[kPlanes] = {};
    sgm::CensusRows rows_{};
};

// Spans of `vectors` vectors of 32 lanes each (0: none, every lane), drifting across the
// range along the row as a guided search's predictions do over a scene's depths.
std::vector<sgm::LaneSpan> driftingSpans(int width, int lanes, int vectors)
{
    if (vectors == 0)
        return {};
    const int units = lanes / kLaneAlign;
    std::vector<sgm::LaneSpan> spans(static_cast<size_t>(width));
    for (int x = 0; x < width; ++x) {
        const int first = (x / 97) % (units - vectors + 1);
        spans[static_cast<size_t>(x)] = {static_cast<uint8_t>(first),
                                         static_cast<uint8_t>(first + vectors)};
    }
    return spans;
}

// Everything a row's three kernels read and write, for one lane count.
struct RowWork {
    int width, lanes;
    CensusRow census;
    std::vector<sgm::LaneSpan> spans;
    std::vector<uint8_t> cost, above_prev, above_cur, along, p2, path_scratch;
    std::vector<uint16_t> sum_scratch, winners_scratch, fields, right_lane;
    sgm::WinnerRows winners{};

    RowWork(int width_px, int lane_count, int span_vectors)
        : width(width_px), lanes(lane_count), census(width_px, lane_count),
          spans(driftingSpans(width_px, lane_count, span_vectors)),
          cost(static_cast<size_t>(width_px) * static_cast<size_t>(lane_count)),
          above_prev(static_cast<size_t>(width_px) * sgm::pathBlockBytes(lane_count), 255),
          above_cur(above_prev.size(), 255), along(above_prev.size(), 255),
          p2(static_cast<size_t>(width_px) + 1, 100),
          path_scratch(2 * sgm::pathBlockBytes(lane_count), 255),
          sum_scratch(sgm::winnersSumScratch(lane_count)),
          winners_scratch(sgm::winnersScratch(width_px, 0, lane_count)),
          fields(5 * static_cast<size_t>(width_px)), right_lane(sgm::rightLaneEntries(width_px))
    {
        const auto w = static_cast<size_t>(width);
        winners = {fields.data(), fields.data() + w, fields.data() + 2 * w, fields.data() + 3 * w,
                   fields.data() + 4 * w};
        costRow();
        // A first row of paths, so that the next rows step from real path costs.
        forward(false);
        std::swap(above_prev, above_cur);
    }
    const sgm::LaneSpan* laneSpans() const { return spans.empty() ? nullptr : spans.data(); }

    void costRow()
    {
        sgm::simdKernels().cost_row(census.rows(), width, 0, lanes, lanes, kCostInvalid,
                                    cost.data(), laneSpans());
    }
    void forward(bool from_previous_row)
    {
        static constexpr int kDx[1] = {0};
        const uint8_t* p2_rows[1] = {p2.data()};
        const uint8_t* prev[1] = {from_previous_row ? above_prev.data() : nullptr};
        uint8_t* cur[1] = {above_cur.data()};
        const sgm::AbovePaths above{1, kDx, p2_rows, prev, cur, laneSpans()};
        sgm::simdKernels().paths_forward(cost.data(), kP1, width, lanes, above, p2.data(),
                                         along.data(), laneSpans());
    }
    void winnersBackward()
    {
        const uint8_t* others[2] = {above_cur.data(), along.data()};
        sgm::simdKernels().winners_backward(cost.data(), p2.data() + 1, kP1, width, lanes,
                                            sgm::PathRows{others, 2}, 0, lanes, path_scratch.data(),
                                            sum_scratch.data(), winners, right_lane.data(),
                                            winners_scratch.data(), laneSpans());
    }
};

enum class Kernel { Cost, Forward, Winners };

void BM_Kernel(benchmark::State& state, Kernel kernel, int width, int lanes, int span_vectors)
{
    RowWork work(width, lanes, span_vectors);
    for (auto _ : state) {
        switch (kernel) {
        case Kernel::Cost:
            work.costRow();
            break;
        case Kernel::Forward:
            work.forward(true);
            break;
        case Kernel::Winners:
            work.winnersBackward();
            break;
        }
        benchmark::ClobberMemory();
    }
    // Seconds per pixel, printed with its prefix ("5.8n": 5.8 ns).
    state.counters["s_per_pixel"] =
        benchmark::Counter(static_cast<double>(state.iterations()) * width,
                           benchmark::Counter::kIsRate | benchmark::Counter::kInvert);
    state.SetLabel(sgm::simdKernels().target);
}

void registerAll()
{
    const std::pair<Kernel, const char*> kernels[] = {{Kernel::Cost, "cost_row"},
                                                      {Kernel::Forward, "paths_forward"},
                                                      {Kernel::Winners, "winners_backward"}};
    for (const auto& [kernel, name] : kernels)
        for (const int width : {640, 1280})
            for (const int lanes : {32, 64, 128, 256})
                for (const int spans : {0, 1, 2}) {
                    if (spans > 0 && (lanes != 256 || width != 1280))
                        continue; // the guided search's case: narrow spans in a wide range
                    const std::string case_name =
                        std::string("kernel:") + name + "/width:" + std::to_string(width) +
                        "/lanes:" + std::to_string(lanes) +
                        "/span_vectors:" + (spans == 0 ? "all" : std::to_string(spans));
                    benchmark::RegisterBenchmark(case_name.c_str(), BM_Kernel, kernel, width, lanes,
                                                 spans);
                }
}

} // namespace
} // namespace stereod::bench

int main(int argc, char** argv)
{
    benchmark::Initialize(&argc, argv);
    stereod::bench::registerAll();
    benchmark::RunSpecifiedBenchmarks();
    benchmark::Shutdown();
    return 0;
}
