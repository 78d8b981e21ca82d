// Result files: PFM and KITTI disparity, millimetre depth PNG, binary PLY, colour depth.

#include <cmath>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <limits>
#include <sstream>
#include <string>
#include <vector>

#include <gtest/gtest.h>
#include <opencv2/imgcodecs.hpp>
#include <unistd.h>

#include "pipeline/depth_io.hpp"

namespace stereod {
namespace {

constexpr float kInf = std::numeric_limits<float>::infinity();

class DepthIo : public ::testing::Test {
  protected:
    std::string path(const std::string& name)
    {
        const std::string p = std::string(STEREOD_BINARY_DIR) + "/pipeline_depth_io_test_" +
                              std::to_string(::getpid()) + "_" + name;
        created_.push_back(p);
        return p;
    }

    void TearDown() override
    {
        for (const std::string& p : created_)
            std::remove(p.c_str());
    }

    static std::string bytes(const std::string& p)
    {
        std::ifstream in(p, std::ios::binary);
        std::ostringstream s;
        s << in.rdbuf();
        return s.str();
    }

  private:
    std::vector<std::string> created_;
};

// A 3-row map whose rows differ, so that the row order in the file is visible.
cv::Mat sampleDisparity()
{
    cv::Mat d(3, 4, CV_32FC1);
    const float values[12] = {1.5f,          2.25f,  kInf,   0.0f,  // top row
                              17.0f,         255.5f, 300.0f, -1.0f, //
                              std::nanf(""), 3.0f,   4.0f,   5.0f}; // bottom row
    std::memcpy(d.data, values, sizeof values);
    return d;
}

TEST_F(DepthIo, PfmRoundTripKeepsValuesAndInfinity)
{
    const cv::Mat d = sampleDisparity();
    const std::string p = path("d.pfm");
    writeDisparity(p, d);
    const cv::Mat back = readDisparity(p);
    ASSERT_EQ(back.type(), CV_32FC1);
    ASSERT_EQ(back.size(), d.size());
    for (int y = 0; y < d.rows; ++y)
        for (int x = 0; x < d.cols; ++x) {
            const float v = d.at<float>(y, x);
            if (std::isnan(v))
                EXPECT_TRUE(std::isinf(back.at<float>(y, x)) && back.at<float>(y, x) > 0)
                    << "NaN is written as Middlebury's +inf";
            else
                EXPECT_EQ(back.at<float>(y, x), v) << x << "," << y;
        }
}

TEST_F(DepthIo, PfmHeaderIsLittleEndianAndRowsRunBottomUp)
{
    const cv::Mat d = sampleDisparity();
    const std::string p = path("layout.pfm");
    writeDisparity(p, d);
    const std::string file = bytes(p);
    const std::string header = "Pf\n4 3\n-1\n";
    ASSERT_EQ(file.substr(0, header.size()), header);
    ASSERT_EQ(file.size(), header.size() + 12 * sizeof(float));
    // The first row in the file is the image's bottom row: NaN (written +inf), 3, 4, 5.
    float first[4];
    std::memcpy(first, file.data() + header.size(), sizeof first);
    EXPECT_TRUE(std::isinf(first[0]));
    EXPECT_EQ(first[1], 3.0f);
    EXPECT_EQ(first[3], 5.0f);
    // The last row in the file is the image's top row.
    float last[4];
    std::memcpy(last, file.data() + header.size() + 8 * sizeof(float), sizeof last);
    EXPECT_EQ(last[0], 1.5f);
    EXPECT_EQ(last[1], 2.25f);
}

TEST_F(DepthIo, ReadsBigEndianPfm)
{
    // Scale +1: big-endian floats, as some tools write them.
    const std::string p = path("be.pfm");
    std::ofstream out(p, std::ios::binary);
    out << "Pf\n2 1\n1.0\n";
    for (float v : {2.5f, -7.0f}) {
        unsigned char b[4];
        std::memcpy(b, &v, 4);
        const unsigned char be[4] = {b[3], b[2], b[1], b[0]};
        out.write(reinterpret_cast<const char*>(be), 4);
    }
    out.close();
    const cv::Mat back = readDisparity(p);
    ASSERT_EQ(back.size(), cv::Size(2, 1));
    EXPECT_EQ(back.at<float>(0, 0), 2.5f);
    EXPECT_EQ(back.at<float>(0, 1), -7.0f);
}

TEST_F(DepthIo, RejectsTruncatedAndForeignPfm)
{
    const std::string truncated = path("truncated.pfm");
    std::ofstream(truncated, std::ios::binary) << "Pf\n4 3\n-1\n" << std::string(20, '\0');
    try {
        readDisparity(truncated);
        FAIL() << "read a truncated file";
    } catch (const std::runtime_error& e) {
        EXPECT_NE(std::string(e.what()).find(truncated), std::string::npos) << e.what();
        EXPECT_NE(std::string(e.what()).find("truncated"), std::string::npos) << e.what();
    }
    const std::string colour = path("colour.pfm");
    std::ofstream(colour, std::ios::binary) << "PF\n1 1\n-1\n" << std::string(12, '\0');
    EXPECT_THROW(readDisparity(colour), std::runtime_error);
}

TEST_F(DepthIo, KittiPngRoundTripAndInvalidConvention)
{
    const cv::Mat d = sampleDisparity();
    const std::string p = path("d.png");
    writeDisparity(p, d);
    const cv::Mat raw = cv::imread(p, cv::IMREAD_UNCHANGED);
    ASSERT_EQ(raw.type(), CV_16UC1);
    EXPECT_EQ(raw.at<uint16_t>(0, 0), 384);   // 1.5 * 256
    EXPECT_EQ(raw.at<uint16_t>(0, 2), 0);     // +inf: invalid
    EXPECT_EQ(raw.at<uint16_t>(0, 3), 0);     // 0 px cannot be told from invalid
    EXPECT_EQ(raw.at<uint16_t>(1, 1), 65408); // 255.5 * 256
    EXPECT_EQ(raw.at<uint16_t>(1, 2), 0);     // 300 px does not fit: invalid, not clipped
    EXPECT_EQ(raw.at<uint16_t>(1, 3), 0);     // negative: invalid
    EXPECT_EQ(raw.at<uint16_t>(2, 0), 0);     // NaN: invalid

    const cv::Mat back = readDisparity(p);
    ASSERT_EQ(back.type(), CV_32FC1);
    EXPECT_EQ(back.at<float>(0, 0), 1.5f);
    EXPECT_EQ(back.at<float>(0, 1), 2.25f);
    EXPECT_EQ(back.at<float>(1, 0), 17.0f);
    EXPECT_EQ(back.at<float>(1, 1), 255.5f);
    EXPECT_TRUE(std::isinf(back.at<float>(0, 2)));
    EXPECT_TRUE(std::isinf(back.at<float>(1, 2)));
    EXPECT_EQ(back.at<float>(2, 3), 5.0f);
}

TEST_F(DepthIo, DepthPngInMillimetresWithZeroInvalid)
{
    cv::Mat z(1, 6, CV_32FC1);
    const float values[6] = {1.2344f, 0.0f, 65.535f, 70.0f, kInf, std::nanf("")};
    std::memcpy(z.data, values, sizeof values);
    const std::string p = path("depth.png");
    writeDepthPng(p, z);
    const cv::Mat raw = cv::imread(p, cv::IMREAD_UNCHANGED);
    ASSERT_EQ(raw.type(), CV_16UC1);
    EXPECT_EQ(raw.at<uint16_t>(0, 0), 1234);
    EXPECT_EQ(raw.at<uint16_t>(0, 1), 0);
    EXPECT_EQ(raw.at<uint16_t>(0, 2), 65535);
    EXPECT_EQ(raw.at<uint16_t>(0, 3), 0); // beyond 65.535 m: invalid, never clipped
    EXPECT_EQ(raw.at<uint16_t>(0, 4), 0);
    EXPECT_EQ(raw.at<uint16_t>(0, 5), 0);

    const cv::Mat back = readDepthPng(p);
    ASSERT_EQ(back.type(), CV_32FC1);
    EXPECT_FLOAT_EQ(back.at<float>(0, 0), 1.234f);
    EXPECT_EQ(back.at<float>(0, 3), 0.0f);
}

TEST_F(DepthIo, DepthToMillimetresReusesTheBuffer)
{
    const cv::Mat z(48, 64, CV_32FC1, cv::Scalar(2.5));
    cv::Mat mm(48, 64, CV_16UC1);
    const uint8_t* before = mm.data;
    depthToMillimetres(z, mm);
    EXPECT_EQ(mm.data, before);
    EXPECT_EQ(mm.at<uint16_t>(10, 10), 2500);
}

TEST_F(DepthIo, PlyHeaderAndPointCount)
{
    const std::vector<CloudPoint> cloud = {
        {0.1f, -0.2f, 1.5f, 128.0f}, {-1.0f, 0.5f, 3.25f, 7.0f}, {0.0f, 0.0f, 0.75f, 255.0f}};
    const std::string p = path("cloud.ply");
    writePly(p, cloud);
    const std::string file = bytes(p);
    const auto end = file.find("end_header\n");
    ASSERT_NE(end, std::string::npos);
    const std::string header = file.substr(0, end);
    EXPECT_EQ(header.rfind("ply\nformat binary_little_endian 1.0\n", 0), 0u) << header;
    EXPECT_NE(header.find("element vertex 3\n"), std::string::npos) << header;
    const auto x = header.find("property float x\n");
    const auto y = header.find("property float y\n");
    const auto zpos = header.find("property float z\n");
    const auto i = header.find("property float intensity\n");
    ASSERT_TRUE(x != std::string::npos && y != std::string::npos && zpos != std::string::npos &&
                i != std::string::npos);
    EXPECT_TRUE(x < y && y < zpos && zpos < i);
    const size_t data = end + std::strlen("end_header\n");
    ASSERT_EQ(file.size() - data, 3 * 4 * sizeof(float));
    float second[4];
    std::memcpy(second, file.data() + data + 4 * sizeof(float), sizeof second);
    EXPECT_EQ(second[0], -1.0f);
    EXPECT_EQ(second[1], 0.5f);
    EXPECT_EQ(second[2], 3.25f);
    EXPECT_EQ(second[3], 7.0f);
}

TEST_F(DepthIo, ColouredPlyHasRedGreenBlueAfterEachPoint)
{
    const std::vector<CloudPoint> cloud = {{0.1f, -0.2f, 1.5f, 128.0f}, {-1.0f, 0.5f, 3.25f, 7.0f}};
    const std::vector<CloudColour> colours = {{255, 0, 10}, {1, 200, 3}};
    const std::string p = path("colour.ply");
    writePly(p, cloud, colours);
    const std::string file = bytes(p);
    const auto end = file.find("end_header\n");
    ASSERT_NE(end, std::string::npos);
    const std::string header = file.substr(0, end);
    const auto i = header.find("property float intensity\n");
    const auto r = header.find("property uchar red\n");
    const auto g = header.find("property uchar green\n");
    const auto b = header.find("property uchar blue\n");
    ASSERT_TRUE(i != std::string::npos && r != std::string::npos && g != std::string::npos &&
                b != std::string::npos)
        << header;
    EXPECT_TRUE(i < r && r < g && g < b);
    const size_t data = end + std::strlen("end_header\n");
    const size_t vertex = 4 * sizeof(float) + 3;
    ASSERT_EQ(file.size() - data, 2 * vertex);
    float second[4];
    std::memcpy(second, file.data() + data + vertex, sizeof second);
    EXPECT_EQ(second[2], 3.25f);
    EXPECT_EQ(static_cast<uint8_t>(file[data + 16]), 255);
    EXPECT_EQ(static_cast<uint8_t>(file[data + 18]), 10);
    EXPECT_EQ(static_cast<uint8_t>(file[data + vertex + 16 + 1]), 200);

    const std::vector<CloudColour> one = {{1, 2, 3}};
    EXPECT_THROW(writePly(path("mismatch.ply"), cloud, one), std::invalid_argument);
}

TEST_F(DepthIo, EmptyCloudIsAValidPly)
{
    const std::string p = path("empty.ply");
    writePly(p, {});
    const std::string file = bytes(p);
    EXPECT_NE(file.find("element vertex 0\n"), std::string::npos);
    EXPECT_EQ(file.substr(file.size() - 11), "end_header\n");
}

TEST_F(DepthIo, ColorizeNearWarmFarCoolInvalidBlack)
{
    cv::Mat z(1, 4, CV_32FC1);
    const float values[4] = {0.5f, 10.0f, 0.0f, kInf};
    std::memcpy(z.data, values, sizeof values);
    const cv::Mat c = colorizeDepth(z, 0.5, 10.0);
    ASSERT_EQ(c.type(), CV_8UC3);
    const cv::Vec3b near = c.at<cv::Vec3b>(0, 0); // BGR
    const cv::Vec3b far = c.at<cv::Vec3b>(0, 1);
    EXPECT_GT(near[2], near[0]) << "near is red-ish";
    EXPECT_GT(far[0], far[2]) << "far is blue-ish";
    EXPECT_EQ(c.at<cv::Vec3b>(0, 2), cv::Vec3b(0, 0, 0));
    EXPECT_EQ(c.at<cv::Vec3b>(0, 3), cv::Vec3b(0, 0, 0));
    EXPECT_THROW(colorizeDepth(z, 0.0, 10.0), std::invalid_argument);
}

TEST_F(DepthIo, WriteErrorsNameTheFile)
{
    const cv::Mat d = sampleDisparity();
    const std::string missing_dir = "/nonexistent-dir-for-stereod/d.pfm";
    try {
        writeDisparity(missing_dir, d);
        FAIL();
    } catch (const std::runtime_error& e) {
        EXPECT_NE(std::string(e.what()).find(missing_dir), std::string::npos) << e.what();
        EXPECT_NE(std::string(e.what()).find("No such file or directory"), std::string::npos)
            << e.what();
    }
    const std::string tiff = path("d.tiff");
    try {
        writeDisparity(tiff, d);
        FAIL();
    } catch (const std::runtime_error& e) {
        EXPECT_NE(std::string(e.what()).find("unsupported disparity format"), std::string::npos)
            << e.what();
    }
    EXPECT_THROW(writeDepthPng(path("depth.png"), cv::Mat()), std::runtime_error);
}

} // namespace
} // namespace stereod
