#include "ros2/messages.hpp"

#include <cstring>
#include <limits>
#include <type_traits>

namespace stereod::ros2 {

namespace {

constexpr std::size_t kEncapsulationSize = 4;
const std::string kSeparator =
    "================================================================================\n";

// Appends CDR fields to a buffer that starts with the encapsulation header; alignment is
// counted from the end of that header.
class CdrWriter {
  public:
    explicit CdrWriter(std::string& out) : out_(out)
    {
        out_.clear();
        out_.append("\x00\x01\x00\x00", kEncapsulationSize); // CDR_LE, options 0
    }

    template <typename T> void put(T value)
    {
        static_assert(std::is_arithmetic_v<T>);
        align(sizeof(T));
        char bytes[sizeof(T)];
        std::memcpy(bytes, &value, sizeof(T)); // little-endian hosts only (static_assert below)
        out_.append(bytes, sizeof(T));
    }
    void str(std::string_view s)
    {
        put(static_cast<uint32_t>(s.size() + 1));
        out_.append(s);
        out_.push_back('\0');
    }
    void octets(const void* data, std::size_t size)
    {
        if (size > std::numeric_limits<uint32_t>::max()) {
            throw CdrError("sequence longer than 4 GiB");
        }
        put(static_cast<uint32_t>(size));
        out_.append(static_cast<const char*>(data), size);
    }
    template <typename T, std::size_t N> void array(const std::array<T, N>& values)
    {
        for (const T& v : values) {
            put(v);
        }
    }
    void header(const Header& h)
    {
        put(h.stamp.sec);
        put(h.stamp.nanosec);
        str(h.frame_id);
    }
    void roi(const RegionOfInterest& r)
    {
        put(r.x_offset);
        put(r.y_offset);
        put(r.height);
        put(r.width);
        put(static_cast<uint8_t>(r.do_rectify ? 1 : 0));
    }
    void image(const Header& h, uint32_t height, uint32_t width, std::string_view encoding,
               uint32_t step, const void* data, std::size_t size)
    {
        header(h);
        put(height);
        put(width);
        str(encoding);
        put(uint8_t{0}); // is_bigendian
        put(step);
        octets(data, size);
    }

  private:
    void align(std::size_t n)
    {
        const std::size_t misalign = (out_.size() - kEncapsulationSize) % n;
        if (misalign != 0) {
            out_.append(n - misalign, '\0');
        }
    }
    std::string& out_;
};

class CdrReader {
  public:
    CdrReader(std::string_view message, const char* type) : data_(message), type_(type)
    {
        if (data_.size() < kEncapsulationSize) {
            fail("shorter than the encapsulation header");
        }
        const auto kind = static_cast<uint8_t>(data_[1]);
        if (data_[0] != 0 || kind != 0x01) {
            const char* what = (data_[0] == 0 && kind == 0x00) ? "big-endian CDR"
                               : (data_[0] == 0 && (kind == 0x07 || kind == 0x09 || kind == 0x0b))
                                   ? "XCDR2"
                                   : "an unknown encapsulation";
            fail(std::string("payload is ") + what + ", only little-endian XCDR1 (00 01) is read");
        }
        pos_ = kEncapsulationSize;
    }

    template <typename T> T get()
    {
        align(sizeof(T));
        need(sizeof(T));
        T value;
        std::memcpy(&value, data_.data() + pos_, sizeof(T));
        pos_ += sizeof(T);
        return value;
    }
    std::string str()
    {
        const uint32_t n = get<uint32_t>();
        need(n);
        std::string_view s = data_.substr(pos_, n);
        pos_ += n;
        // The length counts the terminating NUL; tolerate writers that leave it out.
        if (!s.empty() && s.back() == '\0') {
            s.remove_suffix(1);
        }
        return std::string(s);
    }
    std::string_view octets()
    {
        const uint32_t n = get<uint32_t>();
        need(n);
        const std::string_view s = data_.substr(pos_, n);
        pos_ += n;
        return s;
    }
    template <typename T, std::size_t N> void array(std::array<T, N>& values)
    {
        for (T& v : values) {
            v = get<T>();
        }
    }
    Header header()
    {
        Header h;
        h.stamp.sec = get<int32_t>();
        h.stamp.nanosec = get<uint32_t>();
        h.frame_id = str();
        return h;
    }
    void need(std::size_t n) const
    {
        if (n > data_.size() - pos_) {
            fail("cut short at byte " + std::to_string(pos_) + " (" + std::to_string(n) +
                 " more bytes needed, " + std::to_string(data_.size() - pos_) + " left)");
        }
    }
    [[noreturn]] void fail(const std::string& problem) const
    {
        throw CdrError(std::string(type_) + ": " + problem);
    }

  private:
    void align(std::size_t n)
    {
        const std::size_t misalign = (pos_ - kEncapsulationSize) % n;
        if (misalign != 0) {
            need(n - misalign);
            pos_ += n - misalign;
        }
    }
    std::string_view data_;
    std::size_t pos_ = 0;
    const char* type_;
};

static_assert(__BYTE_ORDER__ == __ORDER_LITTLE_ENDIAN__,
              "the CDR code writes and reads host-order values as little-endian");

const std::string kTimeText = "int32 sec\nuint32 nanosec\n";
const std::string kRegionOfInterestText = "MSG: sensor_msgs/RegionOfInterest\n"
                                          "uint32 x_offset\n"
                                          "uint32 y_offset\n"
                                          "uint32 height\n"
                                          "uint32 width\n"
                                          "bool do_rectify\n";
const std::string kHeaderText = "# Standard metadata for higher-level stamped data types.\n"
                                "builtin_interfaces/Time stamp\n"
                                "string frame_id\n";

std::string withHeader(const std::string& body, const std::string& extra = {})
{
    return body + extra + kSeparator + "MSG: std_msgs/Header\n" + kHeaderText + kSeparator +
           "MSG: builtin_interfaces/Time\n" + kTimeText;
}

} // namespace

Time Time::fromNs(int64_t ns)
{
    int64_t sec = ns / 1'000'000'000;
    int64_t rest = ns % 1'000'000'000;
    if (rest < 0) {
        rest += 1'000'000'000;
        --sec;
    }
    return Time{static_cast<int32_t>(sec), static_cast<uint32_t>(rest)};
}

const std::string& imageSchemaText()
{
    static const std::string text = withHeader("std_msgs/Header header\n"
                                               "uint32 height\n"
                                               "uint32 width\n"
                                               "string encoding\n"
                                               "uint8 is_bigendian\n"
                                               "uint32 step\n"
                                               "uint8[] data\n");
    return text;
}

const std::string& cameraInfoSchemaText()
{
    static const std::string text = withHeader("std_msgs/Header header\n"
                                               "uint32 height\n"
                                               "uint32 width\n"
                                               "string distortion_model\n"
                                               "float64[] d\n"
                                               "float64[9] k\n"
                                               "float64[9] r\n"
                                               "float64[12] p\n"
                                               "uint32 binning_x\n"
                                               "uint32 binning_y\n"
                                               "RegionOfInterest roi\n",
                                               kSeparator + kRegionOfInterestText);
    return text;
}

const std::string& disparityImageSchemaText()
{
    static const std::string text =
        withHeader("std_msgs/Header header\n"
                   "sensor_msgs/Image image\n"
                   "float32 f\n"
                   "float32 t\n"
                   "sensor_msgs/RegionOfInterest valid_window\n"
                   "float32 min_disparity\n"
                   "float32 max_disparity\n"
                   "float32 delta_d\n",
                   kSeparator + "MSG: sensor_msgs/Image\n" +
                       imageSchemaText().substr(0, imageSchemaText().find(kSeparator)) +
                       kSeparator + kRegionOfInterestText);
    return text;
}

const std::string& pointCloud2SchemaText()
{
    static const std::string text = withHeader("std_msgs/Header header\n"
                                               "uint32 height\n"
                                               "uint32 width\n"
                                               "PointField[] fields\n"
                                               "bool is_bigendian\n"
                                               "uint32 point_step\n"
                                               "uint32 row_step\n"
                                               "uint8[] data\n"
                                               "bool is_dense\n",
                                               kSeparator + "MSG: sensor_msgs/PointField\n"
                                                            "uint8 INT8    = 1\n"
                                                            "uint8 UINT8   = 2\n"
                                                            "uint8 INT16   = 3\n"
                                                            "uint8 UINT16  = 4\n"
                                                            "uint8 INT32   = 5\n"
                                                            "uint8 UINT32  = 6\n"
                                                            "uint8 FLOAT32 = 7\n"
                                                            "uint8 FLOAT64 = 8\n"
                                                            "string name\n"
                                                            "uint32 offset\n"
                                                            "uint8 datatype\n"
                                                            "uint32 count\n");
    return text;
}

void serializeImage(const Header& header, uint32_t height, uint32_t width,
                    std::string_view encoding, uint32_t step, const void* data, std::size_t size,
                    std::string& out)
{
    CdrWriter w(out);
    w.image(header, height, width, encoding, step, data, size);
}

void serializeDisparityImage(const DisparityImage& d, const void* data, std::size_t size,
                             std::string& out)
{
    CdrWriter w(out);
    w.header(d.header);
    w.image(d.header, d.height, d.width, "32FC1", d.width * 4, data, size);
    w.put(d.f);
    w.put(d.t);
    w.roi(d.valid_window);
    w.put(d.min_disparity);
    w.put(d.max_disparity);
    w.put(d.delta_d);
}

void serializeCameraInfo(const CameraInfo& info, std::string& out)
{
    CdrWriter w(out);
    w.header(info.header);
    w.put(info.height);
    w.put(info.width);
    w.str(info.distortion_model);
    w.put(static_cast<uint32_t>(info.d.size()));
    for (double v : info.d) {
        w.put(v);
    }
    w.array(info.k);
    w.array(info.r);
    w.array(info.p);
    w.put(info.binning_x);
    w.put(info.binning_y);
    w.roi(info.roi);
}

void serializePointCloud2(const Header& header, uint32_t height, uint32_t width,
                          const std::vector<PointField>& fields, uint32_t point_step,
                          uint32_t row_step, const void* data, std::size_t size, bool is_dense,
                          std::string& out)
{
    CdrWriter w(out);
    w.header(header);
    w.put(height);
    w.put(width);
    w.put(static_cast<uint32_t>(fields.size()));
    for (const PointField& f : fields) {
        w.str(f.name);
        w.put(f.offset);
        w.put(f.datatype);
        w.put(f.count);
    }
    w.put(uint8_t{0}); // is_bigendian
    w.put(point_step);
    w.put(row_step);
    w.octets(data, size);
    w.put(static_cast<uint8_t>(is_dense ? 1 : 0));
}

namespace {

// The service's cloud: x, y, z, intensity and, with `rgb`, the packed colour, float32 each.
void serializeFloatCloud(const Header& header, const float* values, std::size_t points, bool rgb,
                         std::string& out)
{
    static const std::vector<PointField> xyzi = {{"x", 0, PointField::FLOAT32, 1},
                                                 {"y", 4, PointField::FLOAT32, 1},
                                                 {"z", 8, PointField::FLOAT32, 1},
                                                 {"intensity", 12, PointField::FLOAT32, 1}};
    static const std::vector<PointField> xyzirgb = [] {
        std::vector<PointField> fields = xyzi;
        fields.push_back({"rgb", 16, PointField::FLOAT32, 1});
        return fields;
    }();
    const std::vector<PointField>& fields = rgb ? xyzirgb : xyzi;
    const auto point_step = static_cast<uint32_t>(fields.size() * sizeof(float));
    const auto width = static_cast<uint32_t>(points);
    // Dense: the cloud holds only points with a depth, none NaN.
    serializePointCloud2(header, 1, width, fields, point_step, width * point_step, values,
                         points * point_step, true, out);
}

} // namespace

void serializeXyziCloud(const Header& header, const float* xyzi, std::size_t points,
                        std::string& out)
{
    serializeFloatCloud(header, xyzi, points, false, out);
}

void serializeXyziRgbCloud(const Header& header, const float* xyzirgb, std::size_t points,
                           std::string& out)
{
    serializeFloatCloud(header, xyzirgb, points, true, out);
}

ImageView parseImage(std::string_view message)
{
    CdrReader r(message, kImageType);
    ImageView image;
    image.header = r.header();
    image.height = r.get<uint32_t>();
    image.width = r.get<uint32_t>();
    image.encoding = r.str();
    image.is_bigendian = r.get<uint8_t>();
    image.step = r.get<uint32_t>();
    image.data = r.octets();
    if (uint64_t{image.step} * image.height > image.data.size()) {
        r.fail("data holds " + std::to_string(image.data.size()) + " bytes, fewer than step " +
               std::to_string(image.step) + " x height " + std::to_string(image.height));
    }
    return image;
}

CameraInfo parseCameraInfo(std::string_view message)
{
    CdrReader r(message, kCameraInfoType);
    CameraInfo info;
    info.header = r.header();
    info.height = r.get<uint32_t>();
    info.width = r.get<uint32_t>();
    info.distortion_model = r.str();
    const uint32_t n = r.get<uint32_t>();
    r.need(std::size_t{n} * sizeof(double)); // a count past the end fails before resize()
    info.d.resize(n);
    for (double& v : info.d) {
        v = r.get<double>();
    }
    r.array(info.k);
    r.array(info.r);
    r.array(info.p);
    info.binning_x = r.get<uint32_t>();
    info.binning_y = r.get<uint32_t>();
    info.roi.x_offset = r.get<uint32_t>();
    info.roi.y_offset = r.get<uint32_t>();
    info.roi.height = r.get<uint32_t>();
    info.roi.width = r.get<uint32_t>();
    info.roi.do_rectify = r.get<uint8_t>() != 0;
    return info;
}

PointCloud2View parsePointCloud2(std::string_view message)
{
    CdrReader r(message, kPointCloud2Type);
    PointCloud2View cloud;
    cloud.header = r.header();
    cloud.height = r.get<uint32_t>();
    cloud.width = r.get<uint32_t>();
    const uint32_t n = r.get<uint32_t>();
    r.need(std::size_t{n} * 13); // each field takes 13 bytes at least
    cloud.fields.resize(n);
    for (PointField& f : cloud.fields) {
        f.name = r.str();
        f.offset = r.get<uint32_t>();
        f.datatype = r.get<uint8_t>();
        f.count = r.get<uint32_t>();
    }
    cloud.is_bigendian = r.get<uint8_t>() != 0;
    cloud.point_step = r.get<uint32_t>();
    cloud.row_step = r.get<uint32_t>();
    cloud.data = r.octets();
    cloud.is_dense = r.get<uint8_t>() != 0;
    return cloud;
}

} // namespace stereod::ros2
