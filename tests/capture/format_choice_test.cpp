// The automatic format choice as a pure function of what a device offers.
#include <gtest/gtest.h>
#include <linux/videodev2.h>

#include "capture/format_choice.hpp"

namespace stereod {
namespace {

FormatDescription format(uint32_t fourcc, std::vector<FrameSizeDescription> sizes)
{
    FormatDescription f;
    f.fourcc = fourcc;
    f.name = fourccName(fourcc);
    f.sizes = std::move(sizes);
    return f;
}

FrameSizeDescription size(int width, int height, std::vector<double> fps)
{
    FrameSizeDescription s;
    s.width = width;
    s.height = height;
    s.fps = std::move(fps);
    return s;
}

CameraSettings asked(PixelFormatChoice choice, int width, int height, double fps)
{
    CameraSettings settings;
    settings.format = choice;
    settings.width = width;
    settings.height = height;
    settings.fps = fps;
    return settings;
}

TEST(FormatChoice, AutoPrefersGreyThenYuyvThenMjpeg)
{
    const std::vector<FormatDescription> offered = {
        format(V4L2_PIX_FMT_MJPEG, {size(640, 480, {30})}),
        format(V4L2_PIX_FMT_YUYV, {size(640, 480, {30})}),
        format(V4L2_PIX_FMT_GREY, {size(640, 480, {30})}),
    };
    const FormatChoice choice = chooseFormat(offered, asked(PixelFormatChoice::Auto, 640, 480, 30));
    ASSERT_NE(choice.format, nullptr);
    EXPECT_EQ(choice.format->fourcc, V4L2_PIX_FMT_GREY);
    EXPECT_TRUE(choice.passed_over.empty());
}

TEST(FormatChoice, AutoPassesOverAFormatWithoutTheAskedRateAndSaysWhy)
{
    const std::vector<FormatDescription> offered = {
        format(V4L2_PIX_FMT_YUYV, {size(640, 480, {15, 10})}),
        format(V4L2_PIX_FMT_MJPEG, {size(640, 480, {30, 15})}),
    };
    const FormatChoice choice = chooseFormat(offered, asked(PixelFormatChoice::Auto, 640, 480, 30));
    ASSERT_NE(choice.format, nullptr);
    EXPECT_EQ(choice.format->fourcc, V4L2_PIX_FMT_MJPEG);
    EXPECT_EQ(choice.passed_over, "GREY not offered; YUYV not at 640x480 @ 30 fps");
}

TEST(FormatChoice, RateWithinOnePercentMatches)
{
    const std::vector<FormatDescription> offered = {
        format(V4L2_PIX_FMT_GREY, {size(640, 480, {29.97})})};
    EXPECT_NE(chooseFormat(offered, asked(PixelFormatChoice::Auto, 640, 480, 30)).format, nullptr);
    EXPECT_EQ(chooseFormat(offered, asked(PixelFormatChoice::Auto, 640, 480, 25)).format, nullptr);
}

TEST(FormatChoice, SizeRangeWithStepsIsHonoured)
{
    FrameSizeDescription range;
    range.width = 160;
    range.height = 120;
    range.max_width = 1280;
    range.max_height = 960;
    range.step_width = 16;
    range.step_height = 8;
    range.min_fps = 1;
    range.max_fps = 60;
    const std::vector<FormatDescription> offered = {format(V4L2_PIX_FMT_GREY, {range})};
    EXPECT_NE(chooseFormat(offered, asked(PixelFormatChoice::Grey, 640, 480, 30)).format, nullptr);
    EXPECT_EQ(chooseFormat(offered, asked(PixelFormatChoice::Grey, 641, 480, 30)).format, nullptr);
}

TEST(FormatChoice, DriverListingNoSizesIsTrusted)
{
    const std::vector<FormatDescription> offered = {format(V4L2_PIX_FMT_YUYV, {})};
    const FormatChoice choice =
        chooseFormat(offered, asked(PixelFormatChoice::Yuyv, 1920, 1080, 30));
    ASSERT_NE(choice.format, nullptr);
    EXPECT_EQ(choice.format->fourcc, V4L2_PIX_FMT_YUYV);
}

TEST(FormatChoice, RefusalNamesWhatWasAskedAndWhatIsOffered)
{
    std::vector<FormatDescription> offered = {
        format(V4L2_PIX_FMT_YUYV, {size(1280, 720, {10})}),
        format(V4L2_PIX_FMT_RGB24, {size(640, 480, {30})}),
        format(V4L2_PIX_FMT_NV12, {size(640, 480, {30})}),
    };
    const FormatChoice choice = chooseFormat(offered, asked(PixelFormatChoice::Yuyv, 640, 480, 30));
    EXPECT_EQ(choice.format, nullptr);
    EXPECT_EQ(choice.refusal, "cannot deliver YUYV 640x480 @ 30 fps; it offers: YUYV 1280x720 @ "
                              "10 fps; RGB3 640x480 @ 30 fps; NV12 640x480 @ 30 fps (not usable)");
    EXPECT_EQ(
        chooseFormat({}, asked(PixelFormatChoice::Auto, 640, 480, 30)).refusal,
        "cannot deliver GREY, YUYV, MJPG, RGB3 or BGR3 640x480 @ 30 fps; it offers: no formats");
}

TEST(FormatChoice, AutoTakesPackedRgbAfterTheOthersAndNamesWhatItPassedOver)
{
    const std::vector<FormatDescription> offered = {
        format(V4L2_PIX_FMT_BGR24, {size(640, 480, {30})}),
        format(V4L2_PIX_FMT_RGB24, {size(640, 480, {30})}),
        format(V4L2_PIX_FMT_MJPEG, {size(1280, 720, {30})}),
    };
    const FormatChoice choice = chooseFormat(offered, asked(PixelFormatChoice::Auto, 640, 480, 30));
    ASSERT_NE(choice.format, nullptr);
    EXPECT_EQ(choice.format->fourcc, V4L2_PIX_FMT_RGB24);
    EXPECT_EQ(choice.passed_over,
              "GREY not offered; YUYV not offered; MJPG not at 640x480 @ 30 fps");
    const FormatChoice bgr = chooseFormat(offered, asked(PixelFormatChoice::Bgr24, 640, 480, 30));
    ASSERT_NE(bgr.format, nullptr);
    EXPECT_EQ(bgr.format->fourcc, V4L2_PIX_FMT_BGR24);
}

} // namespace
} // namespace stereod
