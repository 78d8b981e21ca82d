#pragma once
// ROS 2 messages in CDR, as ROS 2 bags (MCAP profile `ros2`, message encoding `cdr`) and
// Foxglove carry them: sensor_msgs/msg/Image, sensor_msgs/msg/CameraInfo and
// sensor_msgs/msg/PointCloud2 (with std_msgs/Header and builtin_interfaces/Time), written
// and read, and their `ros2msg` schema texts.
//
// Encoding: XCDR1 (plain CDR) little-endian, as rmw implementations publish it: a 4-byte
// encapsulation header 00 01 00 00, then the fields in order, each primitive aligned to
// its own size (8 for float64) counted from the end of the encapsulation header; strings
// as uint32 length (with the terminating NUL) + bytes + NUL; sequences as uint32 count +
// elements; fixed arrays as their elements.
//
// A library with neither OpenCV nor threads (stereod_ros2_messages), low in the house, so
// that the recorder, the replay source, the calibration formats (CameraInfo) and the live
// view (Foxglove WebSocket, which carries the same CDR messages) share one implementation.
//
// Reentrant: no state outside the arguments. Malformed input throws CdrError.

#include <array>
#include <cstddef>
#include <cstdint>
#include <stdexcept>
#include <string>
#include <string_view>
#include <vector>

namespace stereod::ros2 {

class CdrError : public std::runtime_error {
  public:
    using std::runtime_error::runtime_error;
};

struct Time {
    int32_t sec = 0;
    uint32_t nanosec = 0;

    // From ns on any clock (negative times floor to the second below).
    static Time fromNs(int64_t ns);
    int64_t toNs() const { return int64_t{sec} * 1'000'000'000 + nanosec; }
};

struct Header {
    Time stamp;
    std::string frame_id;
};

// sensor_msgs/msg/Image without its pixels: the header fields, and where the data are.
struct ImageView {
    Header header;
    uint32_t height = 0;
    uint32_t width = 0;
    std::string encoding; // "mono8", "rgb8", "32FC1", ...
    uint8_t is_bigendian = 0;
    uint32_t step = 0;     // bytes per row
    std::string_view data; // borrowed from the serialized message
};

struct RegionOfInterest {
    uint32_t x_offset = 0;
    uint32_t y_offset = 0;
    uint32_t height = 0;
    uint32_t width = 0;
    bool do_rectify = false;
};

struct CameraInfo {
    Header header;
    uint32_t height = 0;
    uint32_t width = 0;
    std::string distortion_model;
    std::vector<double> d;
    std::array<double, 9> k{}; // row-major
    std::array<double, 9> r{};
    std::array<double, 12> p{}; // right camera: p[3] = -fx' * baseline_m
    uint32_t binning_x = 0;
    uint32_t binning_y = 0;
    RegionOfInterest roi;
};

// stereo_msgs/msg/DisparityImage without its pixels (32FC1, row after row): the disparity
// of the rectified left image, f the focal length in px and t the baseline in m, so that
// depth = f * t / d.
struct DisparityImage {
    Header header;
    uint32_t height = 0;
    uint32_t width = 0;
    float f = 0.0f;
    float t = 0.0f;
    RegionOfInterest valid_window;
    float min_disparity = 0.0f;
    float max_disparity = 0.0f;
    float delta_d = 0.0f; // smallest step of disparity the matcher resolves, px
};

struct PointField {
    enum DataType : uint8_t {
        INT8 = 1,
        UINT8 = 2,
        INT16 = 3,
        UINT16 = 4,
        INT32 = 5,
        UINT32 = 6,
        FLOAT32 = 7,
        FLOAT64 = 8
    };
    std::string name;
    uint32_t offset = 0;
    uint8_t datatype = 0;
    uint32_t count = 1;
};

struct PointCloud2View {
    Header header;
    uint32_t height = 0;
    uint32_t width = 0;
    std::vector<PointField> fields;
    bool is_bigendian = false;
    uint32_t point_step = 0;
    uint32_t row_step = 0;
    std::string_view data; // borrowed from the serialized message
    bool is_dense = false;
};

// Schema names and `ros2msg` texts (the message's definition, then each nested type's
// after a line of 80 '=' and `MSG: pkg/Type`), as MCAP Schema records carry them.
inline constexpr const char* kImageType = "sensor_msgs/msg/Image";
inline constexpr const char* kCameraInfoType = "sensor_msgs/msg/CameraInfo";
inline constexpr const char* kPointCloud2Type = "sensor_msgs/msg/PointCloud2";
inline constexpr const char* kDisparityImageType = "stereo_msgs/msg/DisparityImage";
const std::string& imageSchemaText();
const std::string& cameraInfoSchemaText();
const std::string& pointCloud2SchemaText();
const std::string& disparityImageSchemaText();

// The optical frames of the rectified pair (REP 103/105: z forward, x right, y down), as
// recordings and the live view name them.
inline constexpr const char* kLeftOpticalFrame = "stereo_left_optical_frame";
inline constexpr const char* kRightOpticalFrame = "stereo_right_optical_frame";

// Serializers: replace `out` with the whole message, encapsulation header included. `out`
// keeps its capacity, so a reused buffer does not allocate per frame.
void serializeImage(const Header& header, uint32_t height, uint32_t width,
                    std::string_view encoding, uint32_t step, const void* data, std::size_t size,
                    std::string& out);
void serializeCameraInfo(const CameraInfo& info, std::string& out);
// `data`: height * width float32 disparities in px.
void serializeDisparityImage(const DisparityImage& disparity, const void* data, std::size_t size,
                             std::string& out);
void serializePointCloud2(const Header& header, uint32_t height, uint32_t width,
                          const std::vector<PointField>& fields, uint32_t point_step,
                          uint32_t row_step, const void* data, std::size_t size, bool is_dense,
                          std::string& out);

// A dense PointCloud2 of `points` points of x, y, z, intensity float32 (point_step 16),
// `xyzi` holding them in that order: the service's point cloud.
void serializeXyziCloud(const Header& header, const float* xyzi, std::size_t points,
                        std::string& out);
// The same with a fifth float32 field `rgb` (0x00RRGGBB's bits, PCL's packing; point_step
// 20), `xyzirgb` holding the five values of each point: the service's coloured cloud.
void serializeXyziRgbCloud(const Header& header, const float* xyzirgb, std::size_t points,
                           std::string& out);

// Parsers: take the whole message (encapsulation header first). Only little-endian XCDR1
// is accepted (what ROS 2 writes); big-endian or XCDR2 payloads are refused by name.
ImageView parseImage(std::string_view message);
CameraInfo parseCameraInfo(std::string_view message);
PointCloud2View parsePointCloud2(std::string_view message);

} // namespace stereod::ros2
