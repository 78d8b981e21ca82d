#include <cerrno>

#include <fcntl.h>
#include <gtest/gtest.h>

#include "base/system_error.hpp"
#include "base/unique_fd.hpp"

namespace stereod {
namespace {

TEST(SystemError, ErrnoTextIsTheSystemsMessage)
{
    EXPECT_EQ(errnoText(ENOENT), "No such file or directory");
}

TEST(SystemError, ExceptionCarriesWhatAndTheCode)
{
    const std::system_error error = systemError(EACCES, "/dev/video0: open");
    EXPECT_EQ(error.code().value(), EACCES);
    EXPECT_EQ(std::string(error.what()), "/dev/video0: open: Permission denied");
}

TEST(UniqueFd, ClosesOnDestructionAndMovesOwnership)
{
    int raw = -1;
    {
        UniqueFd fd(::open("/dev/null", O_RDONLY | O_CLOEXEC));
        ASSERT_TRUE(fd.valid());
        raw = fd.get();
        UniqueFd moved(std::move(fd));
        EXPECT_FALSE(fd.valid());
        EXPECT_EQ(moved.get(), raw);
    }
    errno = 0;
    EXPECT_EQ(::fcntl(raw, F_GETFD), -1);
    EXPECT_EQ(errno, EBADF);
}

} // namespace
} // namespace stereod
