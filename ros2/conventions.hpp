#pragma once
// Our images in ROS's conventions, for every way they leave the service as ROS 2 messages
// (the live view, DDS): depth as REP 118 has it (32FC1 metres, NaN where there is none),
// disparity as stereo_msgs/DisparityImage has it (invalid = below min_disparity), and the
// rectified pair's CameraInfo (REP 104: the right camera's P[3] = -fx' * baseline).
//
// Reentrant: pure functions; `out` buffers keep their capacity, so a reused one does not
// allocate per frame.

#include <cstdint>
#include <vector>

#include <opencv2/core/mat.hpp>

#include "pipeline/calibration.hpp"
#include "pipeline/stereo_processor.hpp"
#include "ros2/messages.hpp"

namespace stereod::ros2 {

// The result's depth into `out` when it is trusted (`depth_valid`), else "no depth"
// everywhere (zeros of the left image's size): depth the reading refuses to trust goes out
// as none.
void copyTrustedDepth(const DepthResult& result, bool depth_valid, cv::Mat& out);

// `depth_m` (CV_32FC1, metres, 0 = none) with NaN for none.
void depthWithNan(const cv::Mat& depth_m, std::vector<float>& out);

// `disparity` (CV_32FC1, px, invalid = +inf) with min_disparity - 1 for invalid.
void disparityForRos(const cv::Mat& disparity, float min_disparity, std::vector<float>& out);

// The rectified left image as a ROS Image's pixels: the colour (CV_8UC3, BGR) converted
// to rgb8 into `out` when the result has it, else the grey (mono8) copied. Returns the
// encoding, "rgb8" or "mono8".
const char* leftImageForRos(const DepthResult& result, cv::Mat& out);

// A cloud colour as PointCloud2's `rgb` field carries it (PCL's and RViz's convention):
// 0x00RRGGBB, its bits read as a float32.
float packedRgb(CloudColour colour) noexcept;

// Every `step`-th point of the cloud (from the first) into `points`, and when the result
// has its colours, theirs into `colours` (else `colours` is cleared): the subsampled cloud
// the live view and ROS 2 send.
void subsampleCloud(const DepthResult& result, int step, std::vector<CloudPoint>& points,
                    std::vector<CloudColour>& colours);

// `points` with their `colours` interleaved as x, y, z, intensity, rgb float32 (20 bytes a
// point; rgb as packedRgb()), the data of a PointCloud2 with those five fields.
void xyziRgbCloud(const std::vector<CloudPoint>& points, const std::vector<CloudColour>& colours,
                  std::vector<float>& out);

// The CameraInfo of the rectified left (or right) camera, stamped `stamp_ns` (on the
// clock the caller chose) in its optical frame.
CameraInfo rectifiedCameraInfo(const RectifiedGeometry& geometry, bool right, int64_t stamp_ns);

} // namespace stereod::ros2
