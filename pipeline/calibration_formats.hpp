#pragma once
// Other tools' stereo calibration files, to and from StereoCalibration
// (docs/calibration.md, "Other formats"):
//  - ROS camera_calibration: one camera_info YAML per camera (left.yaml, right.yaml), read
//    and written;
//  - OpenCV's stereo_calib sample: intrinsics.yml (M1 D1 M2 D2) and extrinsics.yml
//    (R T R1 R2 P1 P2 Q), read.
//
// Reentrant: no state outside the arguments. Errors are CalibrationError naming the file,
// the line where YAML gives one, the key and the problem.

#include <string>
#include <utility>
#include <vector>

#include <opencv2/core/types.hpp>

#include "pipeline/calibration.hpp"
#include "ros2/messages.hpp"

namespace stereod {

// One camera of a ROS stereo pair, as sensor_msgs/CameraInfo and its YAML file hold it.
// ROS conventions: the right camera's projection has P(0,3) = -fx' * baseline_m (Tx, in
// pixel-metres; negative for a right camera to the right of the left one), the left's 0.
struct RosCameraInfo {
    cv::Size image_size;
    std::string distortion_model = "plumb_bob"; // or "rational_polynomial"
    std::vector<double> d;                      // OpenCV order, 5 or 8 coefficients
    cv::Matx33d k = cv::Matx33d::eye();         // camera matrix
    cv::Matx33d r = cv::Matx33d::eye();         // rectification rotation
    cv::Matx34d p;                              // projection after rectification
};

// The calibration as the two camera_info messages of a ROS stereo pair (what
// exportRosCameraInfo writes to files, and the recorder to MCAP). Throws CalibrationError
// for distortion with no ROS model, naming `left_origin` or `right_origin`.
std::pair<RosCameraInfo, RosCameraInfo>
rosCameraInfoPair(const StereoCalibration& calibration,
                  const std::string& left_origin = "left camera",
                  const std::string& right_origin = "right camera");

// The same as a sensor_msgs/msg/CameraInfo message (header left empty), and back.
ros2::CameraInfo cameraInfoMessage(const RosCameraInfo& info);
RosCameraInfo rosCameraInfoFromMessage(const ros2::CameraInfo& message);

// A full calibration from the two camera_info messages of a ROS stereo pair (see
// importRosCameraInfo); the origins name them in errors and in the log. A rectification
// matrix that is a rotation only to the precision of its printed digits (ROS's writers keep
// 5 or 6) is replaced by the nearest rotation, and the log says so. Throws CalibrationError.
StereoCalibration calibrationFromRosCameraInfo(const RosCameraInfo& left,
                                               const RosCameraInfo& right,
                                               const std::string& left_origin,
                                               const std::string& right_origin);

// A full calibration from the two sensor_msgs/msg/CameraInfo messages of a stereo pair, as
// a bag or a ROS 2 driver's camera_info topics carry them; the origins (the topics) name
// them in errors. Every field of the message is checked before it is used, and a problem
// names the message's own field (width, distortion_model, d, k[4], r, p[3], binning_x,
// roi): sizes up to 8192x8192, plumb_bob with 5 coefficients or rational_polynomial with 8,
// finite numbers, no binning and no region of interest (the images are the full sensor's);
// then calibrationFromRosCameraInfo() does the rest. Throws CalibrationError.
StereoCalibration calibrationFromCameraInfoMessages(const ros2::CameraInfo& left,
                                                    const ros2::CameraInfo& right,
                                                    const std::string& left_origin,
                                                    const std::string& right_origin);

// Reads a ROS stereo pair of camera_info files into a full calibration. R and T are not in
// camera_info: they follow from the rectification, R = R2^T R1 and
// T = R2^T (Tx, Ty, 0) with Tx = P2(0,3) / P2(0,0) (ROS: -baseline, metres). Q and the
// valid regions are derived too. Distortion models plumb_bob and rational_polynomial;
// equidistant (fisheye) is refused.
StereoCalibration importRosCameraInfo(const std::string& left_path, const std::string& right_path);

// Writes the calibration as a ROS pair of camera_info files, `camera_name` + "/left" and
// "/right". Full form: the cameras' intrinsics and distortion (4 or 5 coefficients as
// plumb_bob, 8 as rational_polynomial; 12 or 14 have no ROS model and are refused),
// R1/R2 and P1/P2. Rectified form: undistorted cameras with identity rectification.
void exportRosCameraInfo(const StereoCalibration& calibration, const std::string& left_path,
                         const std::string& right_path, const std::string& camera_name = "stereo");

// The full form of a rectified-only calibration: both cameras undistorted already (the
// rectified camera matrices, no distortion), identity rectification (R1 = R2 = I), R the
// identity and T the baseline along x; the same geometry and depth. What a correction of
// the right camera's rotation (pipeline/calibration_health.hpp) starts from. Throws
// CalibrationError when `rectified` is not rectified-only.
StereoCalibration fullFromRectified(const StereoCalibration& rectified);

// Reads the files of OpenCV's stereo_calib sample. They do not hold the image size; and
// T (hence P2's last column and Q) is in the unit of the square size given to the sample
// (-s, 1 by default: squares): `metres_per_unit` converts it to metres.
StereoCalibration importOpenCvStereoCalib(const std::string& intrinsics_path,
                                          const std::string& extrinsics_path, cv::Size image_size,
                                          double metres_per_unit = 1.0);

} // namespace stereod
