// The recording format: writer and reader, malformed and partial indexes, plain folders.

#include <cerrno>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>

#include <gtest/gtest.h>
#include <opencv2/imgcodecs.hpp>

#include "replay/recording.hpp"
#include "tests/support/data_paths.hpp"
#include "tests/support/process.hpp"
#include "tests/support/recordings.hpp"
#include "tests/support/temp_dir.hpp"

namespace stereod {
namespace {

namespace fs = std::filesystem;
using test::TempDir; // tests/ctl/process.hpp

std::string readText(const std::string& path)
{
    std::ifstream in(path, std::ios::binary);
    std::ostringstream text;
    text << in.rdbuf();
    return text.str();
}

void writeText(const std::string& path, const std::string& text)
{
    std::ofstream out(path, std::ios::binary | std::ios::trunc);
    out << text;
}

// Runs openRecording and returns the error it throws (code 0 when it does not throw).
RecordingError openError(const std::string& path, double fps = 10.0)
{
    try {
        openRecording(path, fps);
    } catch (const RecordingError& e) {
        return e;
    }
    return RecordingError(0, "");
}

TEST(Recording, WriterThenReaderGivesIdenticalPixelsAndStamps)
{
    TempDir tmp;
    std::vector<test::TestPair> pairs = test::tsukubaPairs(5);
    ASSERT_EQ(pairs.size(), 5u);
    test::stampPairs(pairs, 81'263'511'234, 33'333'333);
    const std::string calibration = tmp.file("rig.yaml");
    writeText(calibration, "%YAML:1.0\nfocal_px: 615.0\n");

    const std::string dir = tmp.file("rec");
    test::writeRecording(dir, pairs, calibration);

    EXPECT_EQ(readText(dir + "/frames.csv").substr(0, 46), std::string(kFramesCsvHeader) + "\n");
    const Recording recording = openRecording(dir, 10.0);
    EXPECT_TRUE(recording.has_index);
    EXPECT_EQ(recording.bad_rows, 0u);
    EXPECT_EQ(recording.calibration_path, dir + "/calibration.yaml");
    EXPECT_EQ(readText(recording.calibration_path), readText(calibration));
    ASSERT_EQ(recording.entries.size(), pairs.size());
    for (std::size_t k = 0; k < pairs.size(); ++k) {
        const RecordingEntry& entry = recording.entries[k];
        EXPECT_EQ(entry.index, k);
        EXPECT_EQ(entry.left_stamp_ns, pairs[k].left_stamp_ns);
        EXPECT_EQ(entry.right_stamp_ns, pairs[k].right_stamp_ns);
        EXPECT_EQ(fs::path(entry.left_path).parent_path().filename(), "left");
        EXPECT_EQ(fs::path(entry.right_path).extension(), ".png");
        // PNG is lossless and the images stay 8-bit single channel.
        const cv::Mat left = cv::imread(entry.left_path, cv::IMREAD_UNCHANGED);
        const cv::Mat right = cv::imread(entry.right_path, cv::IMREAD_UNCHANGED);
        EXPECT_TRUE(test::samePixels(left, pairs[k].left)) << entry.left_path;
        EXPECT_TRUE(test::samePixels(right, pairs[k].right)) << entry.right_path;
    }
}

TEST(Recording, WriterWithoutCalibrationLeavesNone)
{
    TempDir tmp;
    std::vector<test::TestPair> pairs = test::tsukubaPairs(1);
    test::writeRecording(tmp.file("rec"), pairs);
    EXPECT_TRUE(openRecording(tmp.file("rec"), 10.0).calibration_path.empty());
}

TEST(Recording, WriterRefusesADirectoryThatHoldsARecording)
{
    TempDir tmp;
    test::writeRecording(tmp.file("rec"), test::tsukubaPairs(1));
    try {
        RecordingWriter again(tmp.file("rec"));
        FAIL() << "a second writer overwrote the recording";
    } catch (const RecordingError& e) {
        EXPECT_EQ(e.code(), EEXIST);
        EXPECT_NE(std::string(e.what()).find("frames.csv"), std::string::npos) << e.what();
    }
}

TEST(Recording, WriterRefusesBadImagesAndLeavesNoRowForThem)
{
    TempDir tmp;
    const std::vector<test::TestPair> pairs = test::tsukubaPairs(2);
    RecordingWriter writer(tmp.file("rec"));
    EXPECT_EQ(writer.write(pairs[0].left, pairs[0].right, 10, 11), 0u);

    // Colour (a colour camera's BGR) is written; 16-bit or four channels are not images
    // of a camera.
    const cv::Mat deep(pairs[1].left.size(), CV_16UC1, cv::Scalar::all(7));
    const cv::Mat four(pairs[1].left.size(), CV_8UC4, cv::Scalar::all(7));
    const cv::Mat bigger(cv::Size(120, 80), CV_8UC1, cv::Scalar::all(7));
    EXPECT_THROW(writer.write(deep, pairs[1].right, 20, 21), RecordingError);
    EXPECT_THROW(writer.write(four, pairs[1].right, 20, 21), RecordingError);
    EXPECT_THROW(writer.write(pairs[1].left, bigger, 20, 21), RecordingError);
    EXPECT_THROW(writer.write(bigger, bigger, 20, 21), RecordingError); // not the first size
    EXPECT_THROW(writer.write(cv::Mat(), pairs[1].right, 20, 21), RecordingError);
    EXPECT_EQ(writer.pairsWritten(), 1u);

    EXPECT_EQ(writer.write(pairs[1].left, pairs[1].right, 20, 21), 1u);
    const Recording recording = openRecording(tmp.file("rec"), 10.0);
    ASSERT_EQ(recording.entries.size(), 2u);
    EXPECT_EQ(recording.entries[1].left_stamp_ns, 20);
    EXPECT_EQ(recording.bad_rows, 0u);
}

TEST(Recording, ReaderSkipsMalformedRowsAndNamesFileAndLine)
{
    TempDir tmp;
    writeText(tmp.file("frames.csv"),
              std::string(kFramesCsvHeader) +
                  "\n"
                  "0,1000,1100,left/a.png,right/a.png\n"         // line 2: good
                  "1,10x0,1100,left/b.png,right/b.png\n"         // line 3: bad left stamp
                  "2,3000\n"                                     // line 4: too few fields
                  "\n"                                           // line 5: blank, ignored
                  "3, 4000 , 3900 ,left/d.png,right/d.png\r\n"   // line 6: good (spaces, CRLF)
                  "-4,5000,5000,left/e.png,right/e.png\n"        // line 7: negative index
                  "5,6000,6000,/abs/f.png,right/f.png\n"         // line 8: absolute name
                  "6,7000,7000,left/g.png,\n"                    // line 9: empty right name
                  "7,8000,8000,left/h.png,right/h.png,extra\n"); // line 10: too many fields
    const Recording recording = openRecording(tmp.path(), 10.0);
    ASSERT_EQ(recording.entries.size(), 2u);
    EXPECT_EQ(recording.entries[0].index, 0u);
    EXPECT_EQ(recording.entries[1].index, 3u);
    EXPECT_EQ(recording.entries[1].left_stamp_ns, 4000);
    EXPECT_EQ(recording.entries[1].right_stamp_ns, 3900);
    EXPECT_EQ(recording.entries[1].left_path, tmp.file("left/d.png"));
    EXPECT_EQ(recording.entries[1].right_path, tmp.file("right/d.png"));

    EXPECT_EQ(recording.bad_rows, 6u);
    ASSERT_EQ(recording.problems.size(), 6u);
    const std::string csv = tmp.file("frames.csv");
    const char* expected[] = {
        ":3: left_stamp_ns",  ":4: expected 5 fields",        ":7: index",
        ":8: left file name", ":9: right file name is empty", ":10: expected 5 fields"};
    for (std::size_t k = 0; k < 6; ++k) {
        EXPECT_EQ(recording.problems[k].rfind(csv, 0), 0u) << recording.problems[k];
        EXPECT_NE(recording.problems[k].find(expected[k]), std::string::npos)
            << recording.problems[k] << " lacks " << expected[k];
    }
}

TEST(Recording, ReaderKeepsAFewMessagesButCountsEveryBadRow)
{
    TempDir tmp;
    std::string text = std::string(kFramesCsvHeader) + "\n0,0,0,left/a.png,right/a.png\n";
    for (int i = 0; i < 50; ++i)
        text += "garbage\n";
    writeText(tmp.file("frames.csv"), text);
    const Recording recording = openRecording(tmp.path(), 10.0);
    EXPECT_EQ(recording.entries.size(), 1u);
    EXPECT_EQ(recording.bad_rows, 50u);
    EXPECT_EQ(recording.problems.size(), Recording::kMaxProblems);
}

TEST(Recording, WrongHeaderFailsTheRecording)
{
    TempDir tmp;
    writeText(tmp.file("frames.csv"), "index,left,right\n0,left/a.png,right/a.png\n");
    const RecordingError error = openError(tmp.path());
    EXPECT_EQ(error.code(), EINVAL);
    EXPECT_NE(std::string(error.what()).find(tmp.file("frames.csv:1:")), std::string::npos)
        << error.what();
    EXPECT_NE(std::string(error.what()).find(kFramesCsvHeader), std::string::npos);
}

TEST(Recording, EmptyIndexFailsTheRecording)
{
    TempDir tmp;
    writeText(tmp.file("frames.csv"), "");
    EXPECT_EQ(openError(tmp.path()).code(), EINVAL);
}

TEST(Recording, IndexWithoutUsableRowsFailsTheRecording)
{
    TempDir tmp;
    writeText(tmp.file("frames.csv"), std::string(kFramesCsvHeader) + "\n0,x,y,a,b\n1,2\n");
    const RecordingError error = openError(tmp.path());
    EXPECT_EQ(error.code(), EINVAL);
    const std::string message = error.what();
    EXPECT_NE(message.find("no usable row"), std::string::npos) << message;
    EXPECT_NE(message.find("frames.csv:2:"), std::string::npos) << message;

    writeText(tmp.file("frames.csv"), std::string(kFramesCsvHeader) + "\n");
    EXPECT_EQ(openError(tmp.path()).code(), EINVAL);
}

TEST(Recording, CutShortIndexStillGivesEveryCompleteRow)
{
    // A recorder killed while writing its last row: the row is cut in the middle.
    TempDir tmp;
    std::vector<test::TestPair> pairs = test::tsukubaPairs(4);
    test::stampPairs(pairs, 5'000'000'000, 50'000'000);
    const std::string dir = tmp.file("rec");
    test::writeRecording(dir, pairs);
    const std::string csv = dir + "/frames.csv";
    const std::string text = readText(csv);
    const std::size_t last_row = text.rfind('\n', text.size() - 2) + 1;
    writeText(csv, text.substr(0, last_row + 6)); // "3,5150" of the fourth row

    const Recording recording = openRecording(dir, 10.0);
    ASSERT_EQ(recording.entries.size(), 3u);
    for (std::size_t k = 0; k < 3; ++k)
        EXPECT_EQ(recording.entries[k].left_stamp_ns, pairs[k].left_stamp_ns);
    EXPECT_EQ(recording.bad_rows, 1u);
    ASSERT_EQ(recording.problems.size(), 1u);
    EXPECT_NE(recording.problems[0].find("frames.csv:5:"), std::string::npos)
        << recording.problems[0];
    EXPECT_NE(recording.problems[0].find("cut short"), std::string::npos) << recording.problems[0];
}

TEST(Recording, PlainFolderPairsLeftAndRightImagesByNameOrder)
{
    TempDir tmp;
    const std::vector<test::TestPair> pairs = test::tsukubaPairs(12, cv::Size(32, 24));
    // Unpadded numbers: left10 must come after left9, not after left1.
    for (std::size_t k = 0; k < pairs.size(); ++k) {
        cv::imwrite(tmp.file("left" + std::to_string(k) + ".png"), pairs[k].left);
        cv::imwrite(tmp.file("Right" + std::to_string(k) + ".png"), pairs[k].right);
    }
    writeText(tmp.file("left_notes.txt"), "not an image");
    writeText(tmp.file("calibration.yaml"), "%YAML:1.0\n");
    fs::create_directory(tmp.file("left_dir.png"));

    const Recording recording = openRecording(tmp.path(), 20.0);
    EXPECT_FALSE(recording.has_index);
    EXPECT_EQ(recording.calibration_path, tmp.file("calibration.yaml"));
    ASSERT_EQ(recording.entries.size(), 12u);
    for (std::size_t k = 0; k < 12; ++k) {
        const RecordingEntry& entry = recording.entries[k];
        EXPECT_EQ(entry.index, k);
        EXPECT_EQ(fs::path(entry.left_path).filename(), "left" + std::to_string(k) + ".png");
        EXPECT_EQ(fs::path(entry.right_path).filename(), "Right" + std::to_string(k) + ".png");
        EXPECT_EQ(entry.left_stamp_ns, static_cast<int64_t>(k) * 50'000'000);
        EXPECT_EQ(entry.right_stamp_ns, entry.left_stamp_ns);
    }
}

TEST(Recording, PlainFolderWithUnequalCountsNamesBoth)
{
    TempDir tmp;
    const std::vector<test::TestPair> pairs = test::tsukubaPairs(3, cv::Size(16, 16));
    for (std::size_t k = 0; k < 3; ++k)
        cv::imwrite(tmp.file("left_" + std::to_string(k) + ".png"), pairs[k].left);
    for (std::size_t k = 0; k < 2; ++k)
        cv::imwrite(tmp.file("right_" + std::to_string(k) + ".png"), pairs[k].right);
    const RecordingError error = openError(tmp.path());
    EXPECT_EQ(error.code(), EINVAL);
    const std::string message = error.what();
    EXPECT_NE(message.find("3 left"), std::string::npos) << message;
    EXPECT_NE(message.find("2 right"), std::string::npos) << message;
    EXPECT_NE(message.find(tmp.path()), std::string::npos) << message;
}

TEST(Recording, PlainFolderNeedsAPositiveFrameRate)
{
    TempDir tmp;
    const std::vector<test::TestPair> pairs = test::tsukubaPairs(1, cv::Size(16, 16));
    cv::imwrite(tmp.file("left.png"), pairs[0].left);
    cv::imwrite(tmp.file("right.png"), pairs[0].right);
    EXPECT_EQ(openError(tmp.path(), 0.0).code(), EINVAL);
    EXPECT_EQ(openError(tmp.path(), -5.0).code(), EINVAL);
    EXPECT_EQ(openRecording(tmp.path(), 5.0).entries.size(), 1u);
}

TEST(Recording, MissingOrEmptyDirectoryIsAnErrorNamingIt)
{
    TempDir tmp;
    const RecordingError missing = openError(tmp.file("nowhere"));
    EXPECT_EQ(missing.code(), ENOENT);
    EXPECT_NE(std::string(missing.what()).find(tmp.file("nowhere")), std::string::npos);

    const RecordingError empty = openError(tmp.path());
    EXPECT_EQ(empty.code(), ENOENT);
    EXPECT_NE(std::string(empty.what()).find(tmp.path()), std::string::npos);

    writeText(tmp.file("file"), "x");
    EXPECT_EQ(openError(tmp.file("file")).code(), ENOTDIR);
}

TEST(Recording, OpenCvSampleFolderReadsAsPlainFolder)
{
    const std::string dir = test::opencvSamplesDir();
    if (!fs::exists(dir + "/left01.jpg"))
        GTEST_SKIP() << "opencv-doc sample data not installed in " << dir;
    // left.jpg/right.jpg plus the 13 chessboard pairs left01..left14 (no 10); the
    // left_intrinsics.yml next to them is no image.
    const Recording recording = openRecording(dir, 10.0);
    ASSERT_EQ(recording.entries.size(), 14u);
    EXPECT_EQ(fs::path(recording.entries[0].left_path).filename(), "left.jpg");
    EXPECT_EQ(fs::path(recording.entries[0].right_path).filename(), "right.jpg");
    EXPECT_EQ(fs::path(recording.entries[1].left_path).filename(), "left01.jpg");
    EXPECT_EQ(fs::path(recording.entries[13].right_path).filename(), "right14.jpg");
}

} // namespace
} // namespace stereod
