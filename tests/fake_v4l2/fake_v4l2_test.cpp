// The fake V4L2 device answers the V4L2 API as a driver would, through libv4l2 (the
// calls production capture code makes): enumeration and negotiation, streaming in each
// format with frames that decode to the source images, the errors of the buffer queue,
// controls, dropped frames, unplug/replug, corrupt frames and the command FIFO.

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <set>
#include <string>
#include <thread>
#include <vector>

#include <fcntl.h>
#include <gtest/gtest.h>
#include <libv4l2.h>
#include <linux/videodev2.h>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <poll.h>
#include <sys/ioctl.h>
#include <sys/mman.h>
#include <sys/stat.h>
#include <time.h>
#include <unistd.h>

#include "tests/fake_v4l2/fake_v4l2.hpp"
#include "tests/support/data_paths.hpp"

namespace {

namespace fs = std::filesystem;

const std::string kSamples = stereod::test::opencvSamplesDir();
constexpr const char* kLeft = "/dev/video-fake-left";
constexpr const char* kById = "/dev/v4l/by-id/usb-Fake_Stereo_Left_0001-video-index0";

int64_t monotonicNs()
{
    timespec ts{};
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return static_cast<int64_t>(ts.tv_sec) * 1'000'000'000 + ts.tv_nsec;
}

// The frames the fake serves for image `file` at the size, in grayscale.
cv::Mat expectedGray(const std::string& file, int width, int height)
{
    cv::Mat image = cv::imread(file, cv::IMREAD_COLOR);
    cv::resize(image, image, cv::Size(width, height), 0.0, 0.0, cv::INTER_AREA);
    cv::Mat gray;
    cv::cvtColor(image, gray, cv::COLOR_BGR2GRAY);
    return gray;
}

class FakeV4l2Test : public ::testing::Test {
  protected:
    void SetUp() override
    {
        dir_ = fs::temp_directory_path() /
               ("fake_v4l2_test_" + std::to_string(getpid()) + "_" +
                ::testing::UnitTest::GetInstance()->current_test_info()->name());
        fs::create_directories(dir_);
    }

    void TearDown() override
    {
        stereod_fake_v4l2_unload();
        fs::remove_all(dir_);
    }

    // Loads a one-device description; `extra` adds keys to the device.
    void load(const std::string& extra = "", const std::string& top = "")
    {
        const fs::path file = dir_ / "devices.yaml";
        std::ofstream(file)
            << top << "devices:\n"
            << "  - path: " << kLeft << "\n"
            << "    by_id: " << fs::path(kById).filename().string() << "\n"
            << "    card: Fake Stereo Left\n"
            << "    images: " << kSamples << "/left0[1-3].jpg\n"
            << "    fps: [100, 30]\n"
            << "    formats:\n"
            << "      - fourcc: GREY\n"
            << "        sizes: [320x240, 640x480@30]\n"
            << "      - fourcc: YUYV\n"
            << "        sizes: [320x240]\n"
            << "      - fourcc: MJPG\n"
            << "        sizes: [320x240, 1280x720@10]\n"
            << "    controls:\n"
            << "      - { name: exposure_auto, default: 3 }\n"
            << "      - { name: exposure_absolute, min: 3, max: 2047, step: 1, default: 250 }\n"
            << "      - { name: gain, min: 0, max: 100, step: 4, default: 32 }\n"
            << "      - { name: power_line_frequency, default: 1 }\n"
            << extra;
        ASSERT_EQ(stereod_fake_v4l2_load(file.c_str()), 0) << stereod_fake_v4l2_last_error();
    }

    std::vector<std::string> images() const
    {
        return {kSamples + "/left01.jpg", kSamples + "/left02.jpg", kSamples + "/left03.jpg"};
    }

    fs::path dir_;
};

// Streams through libv4l2 as a capture loop does; buffers are unmapped and freed in the
// destructor.
class Session {
  public:
    Session(const char* path, uint32_t fourcc, uint32_t width, uint32_t height, int flags = 0)
    {
        fd_ = v4l2_open(path, O_RDWR | flags);
        if (fd_ < 0)
            return;
        v4l2_format fmt{};
        fmt.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
        fmt.fmt.pix.pixelformat = fourcc;
        fmt.fmt.pix.width = width;
        fmt.fmt.pix.height = height;
        format_rc_ = v4l2_ioctl(fd_, VIDIOC_S_FMT, &fmt);
        format_ = fmt.fmt.pix;
    }

    ~Session()
    {
        if (fd_ < 0)
            return;
        int type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
        v4l2_ioctl(fd_, VIDIOC_STREAMOFF, &type);
        for (size_t i = 0; i < maps_.size(); ++i)
            v4l2_munmap(maps_[i], lengths_[i]);
        v4l2_requestbuffers req{};
        req.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
        req.memory = V4L2_MEMORY_MMAP;
        v4l2_ioctl(fd_, VIDIOC_REQBUFS, &req);
        v4l2_close(fd_);
    }

    int fd() const { return fd_; }
    const v4l2_pix_format& format() const { return format_; }
    int formatResult() const { return format_rc_; }

    // REQBUFS, QUERYBUF + mmap, QBUF each; returns the buffer count.
    uint32_t allocate(uint32_t count)
    {
        v4l2_requestbuffers req{};
        req.count = count;
        req.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
        req.memory = V4L2_MEMORY_MMAP;
        EXPECT_EQ(v4l2_ioctl(fd_, VIDIOC_REQBUFS, &req), 0) << std::strerror(errno);
        for (uint32_t i = 0; i < req.count; ++i) {
            v4l2_buffer buf{};
            buf.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
            buf.memory = V4L2_MEMORY_MMAP;
            buf.index = i;
            EXPECT_EQ(v4l2_ioctl(fd_, VIDIOC_QUERYBUF, &buf), 0);
            void* map = v4l2_mmap(nullptr, buf.length, PROT_READ | PROT_WRITE, MAP_SHARED, fd_,
                                  buf.m.offset);
            EXPECT_NE(map, MAP_FAILED) << std::strerror(errno);
            maps_.push_back(static_cast<uint8_t*>(map));
            lengths_.push_back(buf.length);
        }
        return req.count;
    }

    int queue(uint32_t index)
    {
        v4l2_buffer buf{};
        buf.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
        buf.memory = V4L2_MEMORY_MMAP;
        buf.index = index;
        return v4l2_ioctl(fd_, VIDIOC_QBUF, &buf);
    }

    int streamon()
    {
        int type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
        return v4l2_ioctl(fd_, VIDIOC_STREAMON, &type);
    }

    int streamoff()
    {
        int type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
        return v4l2_ioctl(fd_, VIDIOC_STREAMOFF, &type);
    }

    // poll (1 s) then DQBUF; returns the ioctl result (errno in *error).
    int dequeue(v4l2_buffer& buf, int* error)
    {
        pollfd p{fd_, POLLIN, 0};
        ::poll(&p, 1, 1000);
        buf = v4l2_buffer{};
        buf.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
        buf.memory = V4L2_MEMORY_MMAP;
        const int rc = v4l2_ioctl(fd_, VIDIOC_DQBUF, &buf);
        *error = rc == 0 ? 0 : errno;
        return rc;
    }

    const uint8_t* data(uint32_t index) const { return maps_[index]; }

  private:
    int fd_ = -1;
    int format_rc_ = -1;
    v4l2_pix_format format_{};
    std::vector<uint8_t*> maps_;
    std::vector<size_t> lengths_;
};

TEST_F(FakeV4l2Test, QuerycapAndEnumerationDescribeTheDevice)
{
    load();
    const int fd = v4l2_open(kLeft, O_RDWR);
    ASSERT_GE(fd, 0) << std::strerror(errno);
    v4l2_capability cap{};
    ASSERT_EQ(v4l2_ioctl(fd, VIDIOC_QUERYCAP, &cap), 0);
    EXPECT_STREQ(reinterpret_cast<const char*>(cap.driver), "uvcvideo");
    EXPECT_STREQ(reinterpret_cast<const char*>(cap.card), "Fake Stereo Left");
    EXPECT_TRUE(cap.device_caps & V4L2_CAP_VIDEO_CAPTURE);
    EXPECT_TRUE(cap.device_caps & V4L2_CAP_STREAMING);
    EXPECT_TRUE(cap.capabilities & V4L2_CAP_DEVICE_CAPS);

    // Native formats (libv4l2 adds emulated ones flagged V4L2_FMT_FLAG_EMULATED).
    std::vector<uint32_t> native;
    v4l2_fmtdesc desc{};
    desc.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
    for (desc.index = 0; v4l2_ioctl(fd, VIDIOC_ENUM_FMT, &desc) == 0; ++desc.index)
        if (!(desc.flags & V4L2_FMT_FLAG_EMULATED))
            native.push_back(desc.pixelformat);
    EXPECT_EQ(native,
              (std::vector<uint32_t>{V4L2_PIX_FMT_GREY, V4L2_PIX_FMT_YUYV, V4L2_PIX_FMT_MJPEG}));

    std::vector<std::pair<uint32_t, uint32_t>> sizes;
    v4l2_frmsizeenum size{};
    size.pixel_format = V4L2_PIX_FMT_MJPEG;
    for (size.index = 0; v4l2_ioctl(fd, VIDIOC_ENUM_FRAMESIZES, &size) == 0; ++size.index) {
        EXPECT_EQ(size.type, V4L2_FRMSIZE_TYPE_DISCRETE);
        sizes.emplace_back(size.discrete.width, size.discrete.height);
    }
    EXPECT_EQ(sizes, (std::vector<std::pair<uint32_t, uint32_t>>{{320, 240}, {1280, 720}}));

    std::vector<uint32_t> rates;
    v4l2_frmivalenum interval{};
    interval.pixel_format = V4L2_PIX_FMT_GREY;
    interval.width = 320;
    interval.height = 240;
    for (interval.index = 0; v4l2_ioctl(fd, VIDIOC_ENUM_FRAMEINTERVALS, &interval) == 0;
         ++interval.index)
        rates.push_back(interval.discrete.denominator / interval.discrete.numerator);
    EXPECT_EQ(rates, (std::vector<uint32_t>{100, 30}));
    interval = v4l2_frmivalenum{};
    interval.pixel_format = V4L2_PIX_FMT_GREY;
    interval.width = 641;
    interval.height = 480;
    EXPECT_EQ(v4l2_ioctl(fd, VIDIOC_ENUM_FRAMEINTERVALS, &interval), -1) << "not an offered size";
    EXPECT_EQ(errno, EINVAL);
    v4l2_close(fd);
}

TEST_F(FakeV4l2Test, FormatAndRateAdjustToWhatIsOffered)
{
    load();
    const int fd = v4l2_open(kLeft, O_RDWR);
    ASSERT_GE(fd, 0);
    v4l2_format fmt{};
    fmt.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
    fmt.fmt.pix.pixelformat = V4L2_PIX_FMT_GREY;
    fmt.fmt.pix.width = 600;
    fmt.fmt.pix.height = 470;
    ASSERT_EQ(v4l2_ioctl(fd, VIDIOC_TRY_FMT, &fmt), 0);
    EXPECT_EQ(fmt.fmt.pix.width, 640u) << "nearest offered size";
    EXPECT_EQ(fmt.fmt.pix.height, 480u);
    EXPECT_EQ(fmt.fmt.pix.bytesperline, 640u);
    EXPECT_EQ(fmt.fmt.pix.sizeimage, 640u * 480u);

    fmt = v4l2_format{};
    fmt.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
    fmt.fmt.pix.pixelformat = v4l2_fourcc('Y', '1', '6', ' ');
    fmt.fmt.pix.width = 1280;
    fmt.fmt.pix.height = 720;
    ASSERT_EQ(v4l2_ioctl(fd, VIDIOC_S_FMT, &fmt), 0) << "drivers adjust, they do not refuse";
    EXPECT_EQ(fmt.fmt.pix.pixelformat, V4L2_PIX_FMT_GREY);
    EXPECT_EQ(fmt.fmt.pix.width, 640u);

    v4l2_streamparm parm{};
    parm.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
    parm.parm.capture.timeperframe = {1, 60};
    ASSERT_EQ(v4l2_ioctl(fd, VIDIOC_S_PARM, &parm), 0);
    EXPECT_TRUE(parm.parm.capture.capability & V4L2_CAP_TIMEPERFRAME);
    EXPECT_EQ(parm.parm.capture.timeperframe.denominator / parm.parm.capture.timeperframe.numerator,
              30u)
        << "640x480 GREY offers 30 fps only";

    v4l2_format current{};
    current.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
    ASSERT_EQ(v4l2_ioctl(fd, VIDIOC_G_FMT, &current), 0);
    EXPECT_EQ(current.fmt.pix.width, 640u);
    v4l2_close(fd);
}

TEST_F(FakeV4l2Test, ControlsClampMenusRefuseAndUnknownIdsFail)
{
    load();
    const int fd = v4l2_open(kLeft, O_RDWR);
    ASSERT_GE(fd, 0);
    std::set<uint32_t> ids;
    v4l2_queryctrl q{};
    q.id = V4L2_CTRL_FLAG_NEXT_CTRL;
    while (v4l2_ioctl(fd, VIDIOC_QUERYCTRL, &q) == 0) {
        ids.insert(q.id);
        q.id |= V4L2_CTRL_FLAG_NEXT_CTRL;
    }
    EXPECT_TRUE(ids.count(V4L2_CID_EXPOSURE_ABSOLUTE));
    EXPECT_TRUE(ids.count(V4L2_CID_GAIN));
    EXPECT_TRUE(ids.count(V4L2_CID_POWER_LINE_FREQUENCY));

    q = v4l2_queryctrl{};
    q.id = V4L2_CID_EXPOSURE_ABSOLUTE;
    ASSERT_EQ(v4l2_ioctl(fd, VIDIOC_QUERYCTRL, &q), 0);
    EXPECT_TRUE(q.flags & V4L2_CTRL_FLAG_INACTIVE) << "auto exposure is on by default";

    v4l2_control c{V4L2_CID_GAIN, 1000};
    ASSERT_EQ(v4l2_ioctl(fd, VIDIOC_S_CTRL, &c), 0);
    c.value = 0;
    ASSERT_EQ(v4l2_ioctl(fd, VIDIOC_G_CTRL, &c), 0);
    EXPECT_EQ(c.value, 100) << "clamped to max";
    c = {V4L2_CID_GAIN, 37};
    ASSERT_EQ(v4l2_ioctl(fd, VIDIOC_S_CTRL, &c), 0);
    ASSERT_EQ(v4l2_ioctl(fd, VIDIOC_G_CTRL, &c), 0);
    EXPECT_EQ(c.value, 36) << "rounded to the step of 4";

    c = {V4L2_CID_POWER_LINE_FREQUENCY, 7};
    EXPECT_EQ(v4l2_ioctl(fd, VIDIOC_S_CTRL, &c), -1);
    EXPECT_EQ(errno, ERANGE);
    c = {V4L2_CID_SATURATION, 1};
    EXPECT_EQ(v4l2_ioctl(fd, VIDIOC_S_CTRL, &c), -1);
    EXPECT_EQ(errno, EINVAL);

    // Extended controls: all or nothing.
    v4l2_ext_control ext[2]{};
    ext[0].id = V4L2_CID_EXPOSURE_AUTO;
    ext[0].value = V4L2_EXPOSURE_MANUAL;
    ext[1].id = V4L2_CID_EXPOSURE_ABSOLUTE;
    ext[1].value = 100;
    v4l2_ext_controls ctrls{};
    ctrls.which = V4L2_CTRL_WHICH_CUR_VAL;
    ctrls.count = 2;
    ctrls.controls = ext;
    ASSERT_EQ(v4l2_ioctl(fd, VIDIOC_S_EXT_CTRLS, &ctrls), 0) << std::strerror(errno);
    q = v4l2_queryctrl{};
    q.id = V4L2_CID_EXPOSURE_ABSOLUTE;
    ASSERT_EQ(v4l2_ioctl(fd, VIDIOC_QUERYCTRL, &q), 0);
    EXPECT_FALSE(q.flags & V4L2_CTRL_FLAG_INACTIVE) << "manual exposure";
    ext[1].value = 200;
    ext[0].id = V4L2_CID_SATURATION;
    EXPECT_EQ(v4l2_ioctl(fd, VIDIOC_S_EXT_CTRLS, &ctrls), -1);
    EXPECT_EQ(errno, EINVAL);
    c = {V4L2_CID_EXPOSURE_ABSOLUTE, 0};
    ASSERT_EQ(v4l2_ioctl(fd, VIDIOC_G_CTRL, &c), 0);
    EXPECT_EQ(c.value, 100) << "a failed S_EXT_CTRLS changes nothing";
    v4l2_close(fd);
}

struct FormatCase {
    uint32_t fourcc;
    const char* name;
};

class FakeV4l2StreamTest : public FakeV4l2Test, public ::testing::WithParamInterface<FormatCase> {};

TEST_P(FakeV4l2StreamTest, FramesDecodeToTheSourceImages)
{
    load();
    const uint32_t fourcc = GetParam().fourcc;
    Session s(kLeft, fourcc, 320, 240);
    ASSERT_GE(s.fd(), 0);
    ASSERT_EQ(s.formatResult(), 0);
    ASSERT_EQ(s.format().pixelformat, fourcc);
    const uint32_t count = s.allocate(4);
    ASSERT_EQ(count, 4u);
    for (uint32_t i = 0; i < count; ++i)
        ASSERT_EQ(s.queue(i), 0);
    ASSERT_EQ(s.streamon(), 0);

    const std::vector<std::string> files = images();
    int64_t previous_stamp = 0;
    int64_t previous_sequence = -1;
    for (int n = 0; n < 6; ++n) {
        v4l2_buffer buf{};
        int error = 0;
        ASSERT_EQ(s.dequeue(buf, &error), 0) << std::strerror(error);
        const int64_t now = monotonicNs();
        EXPECT_EQ(buf.flags & V4L2_BUF_FLAG_TIMESTAMP_MASK, V4L2_BUF_FLAG_TIMESTAMP_MONOTONIC);
        EXPECT_TRUE(buf.flags & V4L2_BUF_FLAG_DONE);
        EXPECT_TRUE(buf.flags & V4L2_BUF_FLAG_MAPPED);
        EXPECT_FALSE(buf.flags & V4L2_BUF_FLAG_QUEUED);
        EXPECT_EQ(buf.field, V4L2_FIELD_NONE);
        const int64_t stamp =
            buf.timestamp.tv_sec * 1'000'000'000LL + buf.timestamp.tv_usec * 1000LL;
        EXPECT_LE(stamp, now);
        EXPECT_GT(stamp, now - 2'000'000'000LL);
        EXPECT_GT(stamp, previous_stamp);
        EXPECT_GT(static_cast<int64_t>(buf.sequence), previous_sequence);
        previous_stamp = stamp;
        previous_sequence = buf.sequence;

        const cv::Mat expected = expectedGray(files[buf.sequence % files.size()], 320, 240);
        const uint8_t* data = s.data(buf.index);
        cv::Mat gray;
        if (fourcc == V4L2_PIX_FMT_GREY) {
            ASSERT_EQ(buf.bytesused, 320u * 240u);
            gray = cv::Mat(240, 320, CV_8UC1, const_cast<uint8_t*>(data)).clone();
            EXPECT_EQ(cv::norm(gray, expected, cv::NORM_INF), 0.0) << "GREY is exact";
        } else if (fourcc == V4L2_PIX_FMT_YUYV) {
            ASSERT_EQ(buf.bytesused, 2u * 320u * 240u);
            const cv::Mat yuyv(240, 320, CV_8UC2, const_cast<uint8_t*>(data));
            cv::extractChannel(yuyv, gray, 0);
            EXPECT_EQ(cv::norm(gray, expected, cv::NORM_INF), 0.0) << "YUYV luma is exact";
        } else {
            ASSERT_GT(buf.bytesused, 1000u);
            ASSERT_LT(buf.bytesused, 2u * 320u * 240u);
            EXPECT_EQ(data[0], 0xFF);
            EXPECT_EQ(data[1], 0xD8) << "JPEG SOI";
            EXPECT_EQ(data[buf.bytesused - 2], 0xFF);
            EXPECT_EQ(data[buf.bytesused - 1], 0xD9) << "JPEG EOI";
            const cv::Mat jpeg(1, static_cast<int>(buf.bytesused), CV_8UC1,
                               const_cast<uint8_t*>(data));
            gray = cv::imdecode(jpeg, cv::IMREAD_GRAYSCALE);
            ASSERT_EQ(gray.size(), expected.size());
            cv::Mat diff;
            cv::absdiff(gray, expected, diff);
            EXPECT_LT(cv::mean(diff)[0], 2.0) << "MJPEG is close";
        }
        ASSERT_EQ(s.queue(buf.index), 0);
    }
    StereodFakeV4l2Stats stats{};
    ASSERT_EQ(stereod_fake_v4l2_stats(kLeft, &stats), 0);
    EXPECT_EQ(stats.streaming, 1);
    EXPECT_EQ(stats.buffers, 4);
    EXPECT_EQ(stats.buffers_mapped, 4);
    EXPECT_EQ(stats.pixelformat, fourcc);
}

INSTANTIATE_TEST_SUITE_P(Formats, FakeV4l2StreamTest,
                         ::testing::Values(FormatCase{V4L2_PIX_FMT_GREY, "GREY"},
                                           FormatCase{V4L2_PIX_FMT_YUYV, "YUYV"},
                                           FormatCase{V4L2_PIX_FMT_MJPEG, "MJPG"}),
                         [](const ::testing::TestParamInfo<FormatCase>& param) {
                             return param.param.name;
                         });

TEST_F(FakeV4l2Test, BufferQueueErrorsFollowVideobuf2)
{
    load();
    Session s(kLeft, V4L2_PIX_FMT_GREY, 320, 240, O_NONBLOCK);
    ASSERT_GE(s.fd(), 0);
    ASSERT_EQ(s.allocate(2), 2u);

    v4l2_format fmt{};
    fmt.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
    fmt.fmt.pix.pixelformat = V4L2_PIX_FMT_YUYV;
    fmt.fmt.pix.width = 320;
    fmt.fmt.pix.height = 240;
    EXPECT_EQ(v4l2_ioctl(s.fd(), VIDIOC_S_FMT, &fmt), -1) << "buffers exist";
    EXPECT_EQ(errno, EBUSY);

    v4l2_buffer buf{};
    int error = 0;
    EXPECT_EQ(s.dequeue(buf, &error), -1);
    EXPECT_EQ(error, EINVAL) << "DQBUF before STREAMON";
    pollfd p{s.fd(), POLLIN, 0};
    ASSERT_EQ(::poll(&p, 1, 0), 1);
    EXPECT_EQ(p.revents, POLLERR) << "not streaming";

    ASSERT_EQ(s.queue(0), 0);
    EXPECT_EQ(s.queue(0), -1) << "already queued";
    EXPECT_EQ(errno, EINVAL);
    EXPECT_EQ(s.queue(7), -1) << "no such buffer";
    EXPECT_EQ(errno, EINVAL);

    v4l2_requestbuffers req{};
    req.count = 0;
    req.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
    req.memory = V4L2_MEMORY_MMAP;
    EXPECT_EQ(::ioctl(s.fd(), VIDIOC_REQBUFS, &req), -1) << "buffers are mapped";
    EXPECT_EQ(errno, EBUSY);
    v4l2_buffer query{};
    query.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
    query.index = 1;
    ASSERT_EQ(v4l2_ioctl(s.fd(), VIDIOC_QUERYBUF, &query), 0);
    EXPECT_EQ(mmap(nullptr, query.length, PROT_READ, MAP_PRIVATE, s.fd(), query.m.offset),
              MAP_FAILED)
        << "vb2 maps MAP_SHARED only";
    EXPECT_EQ(errno, EINVAL);
    EXPECT_EQ(mmap(nullptr, query.length, PROT_READ, MAP_SHARED, s.fd(), query.m.offset + 4096),
              MAP_FAILED);

    // A stalled device completes nothing: DQBUF on an O_NONBLOCK fd says EAGAIN.
    ASSERT_EQ(stereod_fake_v4l2_stall(kLeft, 60'000), 0);
    ASSERT_EQ(s.streamon(), 0);
    buf = v4l2_buffer{};
    buf.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
    buf.memory = V4L2_MEMORY_MMAP;
    EXPECT_EQ(v4l2_ioctl(s.fd(), VIDIOC_DQBUF, &buf), -1);
    EXPECT_EQ(errno, EAGAIN) << "O_NONBLOCK with nothing done yet";
    ASSERT_EQ(::poll(&p, 1, 0), 0) << "streaming, nothing done: no event";
    ASSERT_EQ(stereod_fake_v4l2_stall(kLeft, 0), 0);
    ASSERT_EQ(s.dequeue(buf, &error), 0) << std::strerror(error);

    // STREAMOFF returns every buffer to the dequeued state.
    ASSERT_EQ(s.queue(buf.index), 0);
    ASSERT_EQ(s.streamoff(), 0);
    for (uint32_t i = 0; i < 2; ++i) {
        query = v4l2_buffer{};
        query.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
        query.index = i;
        ASSERT_EQ(v4l2_ioctl(s.fd(), VIDIOC_QUERYBUF, &query), 0);
        EXPECT_FALSE(query.flags & (V4L2_BUF_FLAG_QUEUED | V4L2_BUF_FLAG_DONE));
    }
    EXPECT_EQ(s.queue(1), 0) << "dequeued buffers can be queued again";

    // A second open file may not touch the queue.
    const int other = v4l2_open(kLeft, O_RDWR);
    ASSERT_GE(other, 0);
    req.count = 2;
    EXPECT_EQ(v4l2_ioctl(other, VIDIOC_REQBUFS, &req), -1);
    EXPECT_EQ(errno, EBUSY);
    v4l2_close(other);
}

TEST_F(FakeV4l2Test, DroppedFramesLeaveSequenceGapsAndUnknownStampsAreFlagged)
{
    load("    drop_every: 3\n    timestamps: unknown\n");
    Session s(kLeft, V4L2_PIX_FMT_GREY, 320, 240);
    ASSERT_EQ(s.allocate(4), 4u);
    for (uint32_t i = 0; i < 4; ++i)
        ASSERT_EQ(s.queue(i), 0);
    ASSERT_EQ(s.streamon(), 0);
    std::vector<uint32_t> sequences;
    for (int n = 0; n < 6; ++n) {
        v4l2_buffer buf{};
        int error = 0;
        ASSERT_EQ(s.dequeue(buf, &error), 0) << std::strerror(error);
        EXPECT_EQ(buf.flags & V4L2_BUF_FLAG_TIMESTAMP_MASK, V4L2_BUF_FLAG_TIMESTAMP_UNKNOWN);
        sequences.push_back(buf.sequence);
        ASSERT_EQ(s.queue(buf.index), 0);
    }
    for (uint32_t seq : sequences)
        EXPECT_NE((seq + 1) % 3, 0u) << "every third frame is lost";
    EXPECT_GT(sequences.back() - sequences.front(), 5u) << "gaps in the sequence";
}

TEST_F(FakeV4l2Test, UnplugFailsEverythingUntilReplug)
{
    load();
    Session s(kLeft, V4L2_PIX_FMT_YUYV, 320, 240);
    ASSERT_EQ(s.allocate(3), 3u);
    for (uint32_t i = 0; i < 3; ++i)
        ASSERT_EQ(s.queue(i), 0);
    ASSERT_EQ(s.streamon(), 0);
    v4l2_buffer buf{};
    int error = 0;
    ASSERT_EQ(s.dequeue(buf, &error), 0);

    // A blocking DQBUF waiting on another thread is woken with ENODEV.
    int blocked_error = 0;
    std::thread waiter([&] {
        v4l2_buffer b{};
        b.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
        b.memory = V4L2_MEMORY_MMAP;
        for (;;) {
            if (v4l2_ioctl(s.fd(), VIDIOC_DQBUF, &b) != 0) {
                blocked_error = errno;
                return;
            }
            v4l2_ioctl(s.fd(), VIDIOC_QBUF, &b);
        }
    });
    ASSERT_EQ(stereod_fake_v4l2_unplug(kById), 0);
    waiter.join();
    EXPECT_EQ(blocked_error, ENODEV);

    pollfd p{s.fd(), POLLIN, 0};
    ASSERT_EQ(::poll(&p, 1, 1000), 1);
    EXPECT_EQ(p.revents & (POLLERR | POLLHUP), POLLERR | POLLHUP);
    v4l2_capability cap{};
    EXPECT_EQ(v4l2_ioctl(s.fd(), VIDIOC_QUERYCAP, &cap), -1);
    EXPECT_EQ(errno, ENODEV);
    EXPECT_EQ(v4l2_open(kLeft, O_RDWR), -1);
    EXPECT_EQ(errno, ENOENT);
    struct stat st {};
    EXPECT_NE(::stat(kLeft, &st), 0);

    ASSERT_EQ(stereod_fake_v4l2_replug(kLeft), 0);
    Session again(kById, V4L2_PIX_FMT_GREY, 320, 240);
    ASSERT_GE(again.fd(), 0) << "opens again by its by-id path";
    ASSERT_EQ(again.allocate(2), 2u);
    ASSERT_EQ(again.queue(0), 0);
    ASSERT_EQ(again.streamon(), 0);
    ASSERT_EQ(again.dequeue(buf, &error), 0) << std::strerror(error);
    EXPECT_EQ(v4l2_ioctl(s.fd(), VIDIOC_QUERYCAP, &cap), -1) << "the old file stays dead";
}

TEST_F(FakeV4l2Test, CorruptFramesAreTruncatedOrFlagged)
{
    load();
    Session s(kLeft, V4L2_PIX_FMT_MJPEG, 320, 240);
    ASSERT_EQ(s.allocate(4), 4u);
    for (uint32_t i = 0; i < 4; ++i)
        ASSERT_EQ(s.queue(i), 0);
    ASSERT_EQ(stereod_fake_v4l2_command("corrupt /dev/video-fake-left 1 truncated"), 0);
    ASSERT_EQ(s.streamon(), 0);
    v4l2_buffer buf{};
    int error = 0;
    ASSERT_EQ(s.dequeue(buf, &error), 0);
    const uint8_t* data = s.data(buf.index);
    EXPECT_FALSE(data[buf.bytesused - 2] == 0xFF && data[buf.bytesused - 1] == 0xD9) << "no EOI";
    ASSERT_EQ(s.queue(buf.index), 0);
    ASSERT_EQ(stereod_fake_v4l2_corrupt(kLeft, 1, "error"), 0);
    // Frames done before the command come first; the next one filled is flagged.
    int flagged = 0;
    for (int n = 0; n < 8 && flagged == 0; ++n) {
        ASSERT_EQ(s.dequeue(buf, &error), 0);
        flagged += (buf.flags & V4L2_BUF_FLAG_ERROR) != 0 ? 1 : 0;
        ASSERT_EQ(s.queue(buf.index), 0);
    }
    EXPECT_EQ(flagged, 1);
    EXPECT_EQ(stereod_fake_v4l2_command("corrupt /dev/video-fake-left 1 sideways"), -EINVAL);
    EXPECT_EQ(stereod_fake_v4l2_command("unplug /dev/video-nothing"), -ENOENT);
}

TEST_F(FakeV4l2Test, DevicesShowInTheirDirectoriesAsCharacterDevicesAndLinks)
{
    load();
    struct stat st {};
    ASSERT_EQ(::stat(kLeft, &st), 0);
    EXPECT_TRUE(S_ISCHR(st.st_mode));
    ASSERT_EQ(::lstat(kById, &st), 0);
    EXPECT_TRUE(S_ISLNK(st.st_mode));
    EXPECT_EQ(fs::canonical(kById), fs::path(kLeft));
    EXPECT_EQ(fs::read_symlink(kById), fs::path("../../video-fake-left"));

    std::vector<std::string> by_id;
    for (const fs::directory_entry& entry : fs::directory_iterator("/dev/v4l/by-id"))
        by_id.push_back(entry.path().string());
    EXPECT_EQ(by_id, std::vector<std::string>{kById});
    bool found = false;
    for (const fs::directory_entry& entry : fs::directory_iterator("/dev"))
        found = found || entry.path() == kLeft;
    EXPECT_TRUE(found);
}

TEST_F(FakeV4l2Test, CommandsArriveThroughTheControlFifo)
{
    const fs::path fifo = dir_ / "control.fifo";
    load("", "control: " + fifo.string() + "\n");
    ASSERT_TRUE(fs::is_fifo(fifo));
    {
        std::ofstream out(fifo);
        out << "unplug " << kLeft << "\n";
    }
    StereodFakeV4l2Stats stats{};
    for (int i = 0; i < 500; ++i) {
        ASSERT_EQ(stereod_fake_v4l2_stats(kLeft, &stats), 0);
        if (!stats.plugged)
            break;
        std::this_thread::sleep_for(std::chrono::milliseconds(10));
    }
    EXPECT_EQ(stats.plugged, 0);
}

TEST_F(FakeV4l2Test, ABadDescriptionNamesFileAndLine)
{
    const fs::path file = dir_ / "bad.yaml";
    std::ofstream(file) << "devices:\n  - path: /dev/video-x\n    images: /nonexistent/*.png\n"
                        << "    formats: [{fourcc: GREY, sizes: [320x240@30]}]\n";
    EXPECT_EQ(stereod_fake_v4l2_load(file.c_str()), -EINVAL);
    const std::string error = stereod_fake_v4l2_last_error();
    EXPECT_NE(error.find("bad.yaml:3"), std::string::npos) << error;
    EXPECT_NE(error.find("match no file"), std::string::npos) << error;
}

} // namespace
