// colour_bench: what carrying the left camera's colour costs the pipeline at 640x480, per
// stage, beside the grey stages it rides along with: the colour left rectified through
// the same fixed-point maps (Rectifier, CV_8UC3), the cloud's colours (PointCloudBuilder::colours),
// and StereoProcessor::process() with and without the colour image. The plausible rig of the
// benchmarks (bench_data: f = 0.9 x width, 0.5 degree rotation, 6 cm baseline) and the
// Aloe photograph in colour, simulated as the rig's raw left view. Every case counts the
// allocations per frame (bench/alloc_counter). Results: bench/README.md, "Colour".
//
// The stages around the processor too: the capture decoders (FrameDecoder) with and without
// the colour beside the grey, for YUYV, MJPEG and RGB24 buffers made from the photograph;
// a bag's rgb8 image decoded for replay with and without its colour; a recording's image
// file (a colour PNG as `stereoctl record` writes it, a colour JPEG) decoded for replay grey
// only (source.replay.colour none) and with its colour, beside the grey file a grey
// recording holds; and what the outputs add: the rectified colour as u8_rgb socket bytes,
// as a ROS rgb8 image, and the coloured cloud packed for PointCloud2.

#include <cstdint>
#include <filesystem>
#include <stdexcept>
#include <string>

#include <benchmark/benchmark.h>
#include <linux/videodev2.h>
#include <opencv2/calib3d.hpp>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <unistd.h>

#include "bench/alloc_counter.hpp"
#include "bench/bench_data.hpp"
#include "capture/frame_decoder.hpp"
#include "daemon/image_payload.hpp"
#include "pipeline/rectifier.hpp"
#include "pipeline/stereo_processor.hpp"
#include "pipeline/triangulation.hpp"
#include "replay/image_decode.hpp"
#include "replay/image_message.hpp"
#include "replay/recording.hpp"
#include "ros2/conventions.hpp"
#include "ros2/messages.hpp"

namespace {

using namespace stereod;

const cv::Size kSize(640, 480);

struct Inputs {
    StereoCalibration calibration;
    bench::ImagePair raw; // grey, the matcher's input
    cv::Mat raw_left_colour;
};

// The colour photograph through the same simulated raw view as the grey pair: each
// channel warped like the grey image (simulateRawPair works on one channel).
const Inputs& inputs()
{
    static const Inputs in = [] {
        Inputs made;
        made.calibration = bench::makePlausibleRigCalibration(kSize);
        const bench::ImagePair scene = bench::loadScene(bench::scenes()[0], kSize);
        made.raw = bench::simulateRawPair(made.calibration, scene);
        const cv::Mat photo =
            cv::imread(std::string(STEREOD_OPENCV_SAMPLES_DIR) + "/aloeL.jpg", cv::IMREAD_COLOR);
        if (photo.empty())
            throw std::runtime_error("OpenCV sample aloeL.jpg missing");
        cv::Mat colour;
        cv::resize(photo, colour, kSize, 0, 0, cv::INTER_AREA);
        cv::Mat planes[3];
        cv::split(colour, planes);
        for (cv::Mat& plane : planes) {
            bench::ImagePair pair{plane, plane};
            plane = bench::simulateRawPair(made.calibration, pair).left;
        }
        cv::merge(planes, 3, made.raw_left_colour);
        return made;
    }();
    return in;
}

template <typename Work> void timed(benchmark::State& state, Work&& work)
{
    work(); // the first frame makes the outputs
    uint64_t cpp = 0, mat = 0, frames = 0;
    for (auto _ : state) {
        const bench::AllocationWindow window;
        work();
        cpp += window.cppAllocations();
        mat += window.matAllocations();
        ++frames;
    }
    state.counters["allocs_per_frame"] = static_cast<double>(cpp) / static_cast<double>(frames);
    state.counters["mat_allocs_per_frame"] = static_cast<double>(mat) / static_cast<double>(frames);
}

void BM_RectifyLeftGrey(benchmark::State& state)
{
    const Rectifier rectifier(inputs().calibration);
    cv::Mat out;
    timed(state, [&] { rectifier.rectifyLeft(inputs().raw.left, out); });
}

void BM_RectifyLeftColour(benchmark::State& state)
{
    const Rectifier rectifier(inputs().calibration);
    cv::Mat out;
    timed(state, [&] { rectifier.rectifyLeft(inputs().raw_left_colour, out); });
}

// The processor's stage timings, averaged, as counters (ms per frame).
void process(benchmark::State& state, bool colour)
{
    ProcessorSettings settings;
    settings.matcher.num_disparities = 128;
    StereoProcessor processor(inputs().calibration, settings);
    DepthResult result;
    const cv::Mat none;
    const cv::Mat& left_colour = colour ? inputs().raw_left_colour : none;
    StageTimings sum;
    uint64_t frame = 0;
    timed(state, [&] {
        processor.process(inputs().raw.left, left_colour, inputs().raw.right, 0, frame++, result);
        sum.rectify_ms += result.timings.rectify_ms;
        sum.colour_ms += result.timings.colour_ms;
        sum.match_ms += result.timings.match_ms;
        sum.cloud_ms += result.timings.cloud_ms;
        sum.cloud_colour_ms += result.timings.cloud_colour_ms;
    });
    const double n = static_cast<double>(frame);
    state.counters["rectify_ms"] = sum.rectify_ms / n;
    state.counters["colour_ms"] = sum.colour_ms / n;
    state.counters["match_ms"] = sum.match_ms / n;
    state.counters["cloud_ms"] = sum.cloud_ms / n;
    state.counters["cloud_colour_ms"] = sum.cloud_colour_ms / n;
    state.counters["points"] = static_cast<double>(result.cloud.size());
}

void BM_ProcessGrey(benchmark::State& state)
{
    process(state, false);
}
void BM_ProcessColour(benchmark::State& state)
{
    process(state, true);
}

// --- capture: one camera buffer to grey, and to grey and colour -------------------------

// The photograph (not the simulated raw view: the decoders do not care) as a camera would
// put it in its buffer.
std::vector<uint8_t> cameraBuffer(uint32_t fourcc)
{
    const cv::Mat& bgr = inputs().raw_left_colour;
    if (fourcc == V4L2_PIX_FMT_MJPEG) {
        std::vector<uint8_t> jpeg;
        cv::imencode(".jpg", bgr, jpeg, {cv::IMWRITE_JPEG_QUALITY, 90});
        return jpeg;
    }
    if (fourcc == V4L2_PIX_FMT_RGB24) {
        cv::Mat rgb;
        cv::cvtColor(bgr, rgb, cv::COLOR_BGR2RGB);
        return {rgb.data, rgb.data + rgb.total() * 3};
    }
    // YUYV: luma and each pair's chroma, full range (what the decoder is told).
    cv::Mat gray, ycrcb;
    cv::cvtColor(bgr, gray, cv::COLOR_BGR2GRAY);
    cv::cvtColor(bgr, ycrcb, cv::COLOR_BGR2YCrCb);
    std::vector<uint8_t> out(bgr.total() * 2);
    for (std::size_t i = 0; i < bgr.total(); i += 2) {
        const auto* c = ycrcb.ptr<cv::Vec3b>() + i;
        out[2 * i] = gray.data[i];
        out[2 * i + 1] = c[0][2];
        out[2 * i + 2] = gray.data[i + 1];
        out[2 * i + 3] = c[0][1];
    }
    return out;
}

void decode(benchmark::State& state, uint32_t fourcc, bool colour)
{
    const std::vector<uint8_t> buffer = cameraBuffer(fourcc);
    const uint32_t bytes_per_line = fourcc == V4L2_PIX_FMT_MJPEG  ? 0
                                    : fourcc == V4L2_PIX_FMT_YUYV ? 2 * kSize.width
                                                                  : 3 * kSize.width;
    FrameDecoder decoder(fourcc, kSize.width, kSize.height, bytes_per_line, true);
    cv::Mat gray(kSize, CV_8UC1);
    cv::Mat bgr;
    if (colour)
        bgr.create(kSize, CV_8UC3);
    timed(state, [&] {
        if (decoder.decode(buffer.data(), buffer.size(), gray, bgr) != DecodeStatus::Ok)
            throw std::runtime_error(decoder.lastError());
    });
}

void BM_CaptureYuyvGrey(benchmark::State& state)
{
    decode(state, V4L2_PIX_FMT_YUYV, false);
}
void BM_CaptureYuyvColour(benchmark::State& state)
{
    decode(state, V4L2_PIX_FMT_YUYV, true);
}
void BM_CaptureMjpegGrey(benchmark::State& state)
{
    decode(state, V4L2_PIX_FMT_MJPEG, false);
}
void BM_CaptureMjpegColour(benchmark::State& state)
{
    decode(state, V4L2_PIX_FMT_MJPEG, true);
}
void BM_CaptureRgb24Grey(benchmark::State& state)
{
    decode(state, V4L2_PIX_FMT_RGB24, false);
}
void BM_CaptureRgb24Colour(benchmark::State& state)
{
    decode(state, V4L2_PIX_FMT_RGB24, true);
}

// --- replay: a bag's rgb8 image to grey, and to grey and colour ------------------------

void replayBag(benchmark::State& state, bool colour)
{
    const cv::Mat& bgr = inputs().raw_left_colour;
    cv::Mat rgb;
    cv::cvtColor(bgr, rgb, cv::COLOR_BGR2RGB);
    std::string message;
    ros2::serializeImage({}, kSize.height, kSize.width, "rgb8", kSize.width * 3, rgb.data,
                         rgb.total() * 3, message);
    cv::Mat gray;
    cv::Mat out_colour;
    std::string reason;
    timed(state, [&] {
        const bool ok = colour ? decodeImageMessage(message, kSize, gray, out_colour, reason)
                               : decodeImageMessage(message, kSize, gray, reason);
        if (!ok)
            throw std::runtime_error(reason);
    });
}

void BM_ReplayBagRgb8Grey(benchmark::State& state)
{
    replayBag(state, false);
}
void BM_ReplayBagRgb8Colour(benchmark::State& state)
{
    replayBag(state, true);
}

// --- replay: a recording's image file to grey, and to grey and colour -------------------

// The photograph as a recording's left image files, in a directory removed at exit: a
// colour and a grey PNG as `stereoctl record` writes them (RecordingWriter), a colour and
// a grey JPEG at quality 90 (a plain folder's).
struct ReplayFiles {
    std::filesystem::path dir;
    std::string colour_png, grey_png, colour_jpeg, grey_jpeg;
    ~ReplayFiles() { std::filesystem::remove_all(dir); }
};

const ReplayFiles& replayFiles()
{
    static const ReplayFiles files = [] {
        ReplayFiles made;
        made.dir =
            std::filesystem::temp_directory_path() / ("colour_bench_" + std::to_string(::getpid()));
        const cv::Mat& bgr = inputs().raw_left_colour;
        const cv::Mat& grey = inputs().raw.left;
        for (const bool colour : {true, false}) {
            const std::string dir = (made.dir / (colour ? "colour" : "grey")).string();
            RecordingWriter writer(dir);
            writer.write(colour ? bgr : grey, grey, 0, 0);
            (colour ? made.colour_png : made.grey_png) = dir + "/left/000000.png";
        }
        made.colour_jpeg = (made.dir / "colour.jpg").string();
        made.grey_jpeg = (made.dir / "grey.jpg").string();
        cv::imwrite(made.colour_jpeg, bgr, {cv::IMWRITE_JPEG_QUALITY, 90});
        cv::imwrite(made.grey_jpeg, grey, {cv::IMWRITE_JPEG_QUALITY, 90});
        return made;
    }();
    return files;
}

void replayFile(benchmark::State& state, const std::string& path, bool colour)
{
    std::vector<uint8_t> bytes;
    cv::Mat grey, out_colour;
    std::string reason;
    int code = 0;
    timed(state, [&] {
        if (!decodeImageFile(path, kSize, "640x480", bytes, grey, reason, code,
                             colour ? &out_colour : nullptr))
            throw std::runtime_error(path + ": " + reason);
    });
}

void BM_ReplayPngGreyFile(benchmark::State& state)
{
    replayFile(state, replayFiles().grey_png, false);
}
void BM_ReplayPngColourFileGreyOnly(benchmark::State& state)
{
    replayFile(state, replayFiles().colour_png, false);
}
void BM_ReplayPngColourFile(benchmark::State& state)
{
    replayFile(state, replayFiles().colour_png, true);
}
void BM_ReplayJpegGreyFile(benchmark::State& state)
{
    replayFile(state, replayFiles().grey_jpeg, false);
}
void BM_ReplayJpegColourFileGreyOnly(benchmark::State& state)
{
    replayFile(state, replayFiles().colour_jpeg, false);
}
void BM_ReplayJpegColourFile(benchmark::State& state)
{
    replayFile(state, replayFiles().colour_jpeg, true);
}

// --- outputs: the rectified colour and the coloured cloud as they leave the service -----

const DepthResult& colourResult()
{
    static const DepthResult made = [] {
        ProcessorSettings settings;
        settings.matcher.num_disparities = 128;
        StereoProcessor processor(inputs().calibration, settings);
        DepthResult result;
        processor.process(inputs().raw.left, inputs().raw_left_colour, inputs().raw.right, 0, 0,
                          result);
        return result;
    }();
    return made;
}

void BM_SocketLeftColourRgb(benchmark::State& state)
{
    const DepthResult& result = colourResult();
    std::string out;
    out.reserve(result.left_rectified_colour.total() * 3);
    timed(state, [&] {
        out.clear();
        appendBgrAsRgb(out, result.left_rectified_colour);
    });
}

void BM_Ros2LeftImageRgb8(benchmark::State& state)
{
    const DepthResult& result = colourResult();
    cv::Mat image;
    std::string message;
    timed(state, [&] {
        const char* encoding = ros2::leftImageForRos(result, image);
        ros2::serializeImage({}, image.rows, image.cols, encoding, image.cols * 3, image.data,
                             image.total() * 3, message);
    });
}

void BM_Ros2CloudRgb(benchmark::State& state)
{
    const DepthResult& result = colourResult();
    std::vector<CloudPoint> points;
    std::vector<CloudColour> colours;
    std::vector<float> packed;
    std::string message;
    timed(state, [&] {
        ros2::subsampleCloud(result, 1, points, colours);
        ros2::xyziRgbCloud(points, colours, packed);
        ros2::serializeXyziRgbCloud({}, packed.data(), points.size(), message);
    });
    state.counters["points"] = static_cast<double>(points.size());
}

void BM_Ros2CloudGrey(benchmark::State& state)
{
    DepthResult result = colourResult();
    result.cloud_colour.clear();
    std::vector<CloudPoint> points;
    std::vector<CloudColour> colours;
    std::string message;
    timed(state, [&] {
        ros2::subsampleCloud(result, 1, points, colours);
        ros2::serializeXyziCloud({}, reinterpret_cast<const float*>(points.data()), points.size(),
                                 message);
    });
}

BENCHMARK(BM_CaptureYuyvGrey)->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK(BM_CaptureYuyvColour)->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK(BM_CaptureMjpegGrey)->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK(BM_CaptureMjpegColour)->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK(BM_CaptureRgb24Grey)->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK(BM_CaptureRgb24Colour)->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK(BM_ReplayBagRgb8Grey)->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK(BM_ReplayBagRgb8Colour)->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK(BM_ReplayPngGreyFile)->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK(BM_ReplayPngColourFileGreyOnly)->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK(BM_ReplayPngColourFile)->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK(BM_ReplayJpegGreyFile)->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK(BM_ReplayJpegColourFileGreyOnly)->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK(BM_ReplayJpegColourFile)->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK(BM_SocketLeftColourRgb)->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK(BM_Ros2LeftImageRgb8)->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK(BM_Ros2CloudGrey)->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK(BM_Ros2CloudRgb)->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK(BM_RectifyLeftGrey)->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK(BM_RectifyLeftColour)->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK(BM_ProcessGrey)->Unit(benchmark::kMillisecond)->UseRealTime()->MinTime(2.0);
BENCHMARK(BM_ProcessColour)->Unit(benchmark::kMillisecond)->UseRealTime()->MinTime(2.0);

} // namespace

int main(int argc, char** argv)
{
    stereod::bench::installCountingMatAllocator();
    benchmark::Initialize(&argc, argv);
    if (benchmark::ReportUnrecognizedArguments(argc, argv))
        return 2;
    benchmark::RunSpecifiedBenchmarks();
    benchmark::Shutdown();
    return 0;
}
