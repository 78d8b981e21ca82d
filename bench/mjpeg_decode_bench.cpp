// MJPEG to grayscale: the decoder the capture path uses (FrameDecoder: TurboJPEG,
// TJPF_GRAY + TJFLAG_FASTDCT, into the frame's own buffer) against
// cv::imdecode(IMREAD_GRAYSCALE), on the Aloe photograph encoded as a camera would
// (colour JPEG, quality 90) at 640x480 and 1280x720. Also YUYV's luma extraction, for
// scale. Results: docs/cameras.md.

#include <string>
#include <vector>

#include <benchmark/benchmark.h>
#include <linux/videodev2.h>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "capture/frame_decoder.hpp"

namespace {

std::vector<uint8_t> cameraJpeg(cv::Size size)
{
    const cv::Mat aloe = cv::imread(std::string(STEREOD_OPENCV_SAMPLES_DIR) + "/aloeL.jpg");
    if (aloe.empty())
        throw std::runtime_error("OpenCV sample aloeL.jpg missing");
    cv::Mat resized;
    cv::resize(aloe, resized, size, 0, 0, cv::INTER_AREA);
    std::vector<uint8_t> jpeg;
    cv::imencode(".jpg", resized, jpeg, {cv::IMWRITE_JPEG_QUALITY, 90});
    return jpeg;
}

void BM_MjpegTurboJpegGray(benchmark::State& state)
{
    const cv::Size size(static_cast<int>(state.range(0)), static_cast<int>(state.range(1)));
    const std::vector<uint8_t> jpeg = cameraJpeg(size);
    stereod::FrameDecoder decoder(V4L2_PIX_FMT_MJPEG, size.width, size.height, 0);
    cv::Mat gray(size, CV_8UC1);
    for (auto _ : state) {
        if (decoder.decode(jpeg.data(), jpeg.size(), gray) != stereod::DecodeStatus::Ok)
            state.SkipWithError(decoder.lastError());
        benchmark::DoNotOptimize(gray.data);
    }
    state.counters["fps"] =
        benchmark::Counter(static_cast<double>(state.iterations()), benchmark::Counter::kIsRate);
}

void BM_MjpegOpenCvImdecodeGray(benchmark::State& state)
{
    const cv::Size size(static_cast<int>(state.range(0)), static_cast<int>(state.range(1)));
    const std::vector<uint8_t> jpeg = cameraJpeg(size);
    cv::Mat gray(size, CV_8UC1);
    for (auto _ : state) {
        cv::imdecode(jpeg, cv::IMREAD_GRAYSCALE, &gray);
        benchmark::DoNotOptimize(gray.data);
    }
    state.counters["fps"] =
        benchmark::Counter(static_cast<double>(state.iterations()), benchmark::Counter::kIsRate);
}

void BM_YuyvLuma(benchmark::State& state)
{
    const cv::Size size(static_cast<int>(state.range(0)), static_cast<int>(state.range(1)));
    const std::vector<uint8_t> yuyv(static_cast<std::size_t>(size.area()) * 2, 128);
    stereod::FrameDecoder decoder(V4L2_PIX_FMT_YUYV, size.width, size.height,
                                  static_cast<uint32_t>(size.width * 2));
    cv::Mat gray(size, CV_8UC1);
    for (auto _ : state) {
        decoder.decode(yuyv.data(), yuyv.size(), gray);
        benchmark::DoNotOptimize(gray.data);
    }
    state.counters["fps"] =
        benchmark::Counter(static_cast<double>(state.iterations()), benchmark::Counter::kIsRate);
}

} // namespace

BENCHMARK(BM_MjpegTurboJpegGray)
    ->Args({640, 480})
    ->Args({1280, 720})
    ->Unit(benchmark::kMicrosecond);
BENCHMARK(BM_MjpegOpenCvImdecodeGray)
    ->Args({640, 480})
    ->Args({1280, 720})
    ->Unit(benchmark::kMicrosecond);
BENCHMARK(BM_YuyvLuma)->Args({640, 480})->Args({1280, 720})->Unit(benchmark::kMicrosecond);

BENCHMARK_MAIN();
