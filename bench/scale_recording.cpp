// scale_recording: a recording made larger, as a camera of more pixels on the same rig would
// have taken it: every image scaled by an integer factor and cut to its middle rows, and the
// calibration changed to match exactly, so that the service replays it with the rig's real
// geometry. bench/service_compare.sh --720p makes the real rig's 1280x720 recording with it
// (scale 2, height 720: 640x480 to 1280x960, cut to its middle 720 rows).
//
//   scale_recording SOURCE_DIR OUT_DIR [--scale S] [--height H] [--jpeg-quality Q]
//
// The scaling maps a source pixel (x, y) to (S·x, S·y − top) exactly, where top = (S·height −
// H) / 2 rows are cut above (cv::warpAffine, bilinear; the enlarged image's last S − 1 columns
// repeat the source's edge). The calibration's pixel quantities follow the same map: the
// camera matrices and P1, P2 are multiplied on the left by A = [S 0 0; 0 S −top; 0 0 1] (fx,
// fy, cx and P(0,3) = −f·B times S; cy times S, then minus top), Q becomes S·Q·C with C the
// inverse of the map on (x, y, d, 1) (disparities scale by S too), the valid ROIs are mapped
// and cut to the image, the RMS and epipolar errors (pixels) scale by S. The distortion
// coefficients (of normalised coordinates), R, T, R1 and R2 do not change. A rectified-only
// calibration scales its focal length, principal point and doffs the same way.
//
// OUT_DIR gets frames.csv (the source's index and stamps, the new file names), left/ and
// right/ (each image in its source file's format: JPEG at --jpeg-quality, default 95, or
// PNG) and calibration.yaml. It is written as OUT_DIR.partial and renamed when complete;
// an OUT_DIR that exists is refused. Exit status 1 with the reason on stderr when the
// recording cannot be read, has no calibration, has images of another size than its
// calibration's or cannot be written.

#include <cctype>
#include <cstdio>
#include <exception>
#include <filesystem>
#include <fstream>
#include <stdexcept>
#include <string>
#include <vector>

#include <CLI/CLI.hpp>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "pipeline/calibration.hpp"
#include "replay/recording.hpp"

namespace fs = std::filesystem;
using namespace stereod;

namespace {

// The map from source pixels to the output's: (x, y) -> (scale·x, scale·y − top).
struct PixelMap {
    int scale = 2;
    int top = 0; // rows of the enlarged image cut above the output
    cv::Size size;

    cv::Matx33d matrix() const
    {
        return {double(scale), 0, 0, 0, double(scale), -double(top), 0, 0, 1};
    }
};

cv::Rect mapRoi(const cv::Rect& roi, const PixelMap& map)
{
    const cv::Rect mapped(roi.x * map.scale, roi.y * map.scale - map.top, roi.width * map.scale,
                          roi.height * map.scale);
    return mapped & cv::Rect(0, 0, map.size.width, map.size.height);
}

StereoCalibration mapCalibration(StereoCalibration c, const PixelMap& map)
{
    const double s = map.scale;
    if (c.kind == StereoCalibration::Kind::RectifiedOnly) {
        RectifiedGeometry& g = c.rectified;
        g.image_size = ImageSize{map.size.width, map.size.height};
        g.focal_px *= s;
        g.cx_px *= s;
        g.cy_px = g.cy_px * s - map.top;
        g.doffs_px *= s;
        return c;
    }
    const cv::Matx33d a = map.matrix();
    c.left.camera_matrix = a * c.left.camera_matrix;
    c.right.camera_matrix = a * c.right.camera_matrix;
    c.P1 = a * c.P1;
    c.P2 = a * c.P2;
    // (x, y, d, 1) of the source from the output's (x', y', d', 1).
    const cv::Matx44d back(1 / s, 0, 0, 0, 0, 1 / s, 0, map.top / s, 0, 0, 1 / s, 0, 0, 0, 0, 1);
    c.Q = s * (c.Q * back);
    c.valid_roi_left = mapRoi(c.valid_roi_left, map);
    c.valid_roi_right = mapRoi(c.valid_roi_right, map);
    if (c.rms_px)
        *c.rms_px *= s;
    if (c.epipolar_error_px)
        *c.epipolar_error_px *= s;
    c.rectified = rectifiedFromProjections(c.P1, c.P2, map.size);
    return c;
}

std::string lowerExtension(const std::string& path)
{
    std::string ext = fs::path(path).extension().string();
    for (char& ch : ext)
        ch = static_cast<char>(std::tolower(static_cast<unsigned char>(ch)));
    return ext;
}

// Reads, maps and writes one image; returns its name relative to the recording.
std::string mapImage(const std::string& source, const std::string& side, std::size_t position,
                     const PixelMap& map, cv::Size expected, int jpeg_quality,
                     const fs::path& out_dir)
{
    const cv::Mat image = cv::imread(source, cv::IMREAD_UNCHANGED);
    if (image.empty())
        throw std::runtime_error(source + ": cannot be read as an image");
    if (image.depth() != CV_8U)
        throw std::runtime_error(source + ": not an 8-bit image");
    if (image.size() != expected)
        throw std::runtime_error(source + ": " + std::to_string(image.cols) + "x" +
                                 std::to_string(image.rows) + " but the calibration is for " +
                                 std::to_string(expected.width) + "x" +
                                 std::to_string(expected.height) + " images");
    cv::Mat mapped;
    const cv::Matx33d a = map.matrix();
    cv::warpAffine(image, mapped, cv::Matx23d(a(0, 0), a(0, 1), a(0, 2), a(1, 0), a(1, 1), a(1, 2)),
                   map.size, cv::INTER_LINEAR, cv::BORDER_REPLICATE);

    const std::string ext = lowerExtension(source);
    const bool jpeg = ext == ".jpg" || ext == ".jpeg";
    char name[32];
    std::snprintf(name, sizeof name, "%06zu%s", position, jpeg ? ".jpg" : ".png");
    const std::string relative = side + "/" + name;
    const std::vector<int> params =
        jpeg ? std::vector<int>{cv::IMWRITE_JPEG_QUALITY, jpeg_quality} : std::vector<int>{};
    if (!cv::imwrite((out_dir / relative).string(), mapped, params))
        throw std::runtime_error((out_dir / relative).string() + ": cannot be written");
    return relative;
}

} // namespace

int main(int argc, char** argv)
{
    std::string source_dir, out_dir;
    int scale = 2, height = 720, jpeg_quality = 95;
    CLI::App app("A recording scaled by an integer factor and cut to its middle rows, with "
                 "its calibration changed to match");
    app.add_option("source", source_dir, "recording directory (frames.csv, calibration.yaml)")
        ->required();
    app.add_option("out", out_dir, "directory to create")->required();
    app.add_option("--scale", scale, "integer scale factor")->check(CLI::Range(1, 8));
    app.add_option("--height", height, "rows kept, the middle ones of the scaled image")
        ->check(CLI::Range(1, 16384));
    app.add_option("--jpeg-quality", jpeg_quality, "quality of JPEG images written")
        ->check(CLI::Range(1, 100));
    CLI11_PARSE(app, argc, argv);

    try {
        const Recording recording = openRecording(source_dir, 1.0);
        if (!recording.has_index)
            throw std::runtime_error(source_dir + ": no frames.csv (a plain folder of images)");
        if (recording.bad_rows > 0)
            throw std::runtime_error(recording.problems.front() + " (and " +
                                     std::to_string(recording.bad_rows - 1) + " more)");
        if (recording.calibration_path.empty())
            throw std::runtime_error(source_dir + ": no calibration.yaml");
        const StereoCalibration calibration = loadCalibration(recording.calibration_path);
        const cv::Size source_size(calibration.rectified.image_size.width,
                                   calibration.rectified.image_size.height);

        PixelMap map;
        map.scale = scale;
        const int scaled_height = source_size.height * scale;
        if (height > scaled_height || (scaled_height - height) % 2 != 0)
            throw std::runtime_error(
                "--height " + std::to_string(height) + ": must be at most the scaled height " +
                std::to_string(scaled_height) + " and differ from it by an even number of rows");
        map.top = (scaled_height - height) / 2;
        map.size = cv::Size(source_size.width * scale, height);
        const StereoCalibration mapped = mapCalibration(calibration, map);

        const fs::path out(out_dir);
        if (fs::exists(out))
            throw std::runtime_error(out_dir + ": exists; remove it to make it again");
        const fs::path partial = out.string() + ".partial";
        fs::remove_all(partial);
        fs::create_directories(partial / "left");
        fs::create_directories(partial / "right");
        saveCalibration(mapped, (partial / kCalibrationName).string());

        std::ofstream csv(partial / kFramesCsvName);
        csv << kFramesCsvHeader << '\n';
        for (std::size_t i = 0; i < recording.entries.size(); ++i) {
            const RecordingEntry& e = recording.entries[i];
            const std::string left =
                mapImage(e.left_path, "left", i, map, source_size, jpeg_quality, partial);
            const std::string right =
                mapImage(e.right_path, "right", i, map, source_size, jpeg_quality, partial);
            csv << e.index << ',' << e.left_stamp_ns << ',' << e.right_stamp_ns << ',' << left
                << ',' << right << '\n';
        }
        csv.close();
        if (!csv)
            throw std::runtime_error((partial / kFramesCsvName).string() + ": cannot be written");
        fs::rename(partial, out);

        std::printf("scale_recording: %zu pairs, %dx%d scaled by %d to %dx%d, %d rows cut above "
                    "and below: %s (focal length %.2f -> %.2f px, cy %.2f -> %.2f px)\n",
                    recording.entries.size(), source_size.width, source_size.height, scale,
                    map.size.width, scaled_height, map.top, out_dir.c_str(),
                    calibration.rectified.focal_px, mapped.rectified.focal_px,
                    calibration.rectified.cy_px, mapped.rectified.cy_px);
        return 0;
    } catch (const std::exception& e) {
        std::fprintf(stderr, "scale_recording: %s\n", e.what());
        return 1;
    }
}
