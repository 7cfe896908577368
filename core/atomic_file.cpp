#include "core/atomic_file.h"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <filesystem>
#include <random>
#include <sstream>

#include "core/errors.h"

namespace flankcam {
namespace fs = std::filesystem;

namespace {
// 64 random bits (getrandom through random_device): nobody can plant a file at the name in advance.
std::string random_tag() {
  std::random_device rd;
  const unsigned long long v = (static_cast<unsigned long long>(rd()) << 32) ^ rd();
  char buf[17];
  std::snprintf(buf, sizeof buf, "%016llx", v);
  return buf;
}

// Same directory (rename is atomic there); the extension stays last for writers that dispatch on it.
std::string temporary_name(const fs::path& p) {
  return (p.parent_path() / ("." + p.stem().string() + ".tmp-" + random_tag() + p.extension().string())).string();
}

std::string reason(int err) { return std::strerror(err); }

void write_all(int fd, const std::string& path, const std::string& bytes) {
  size_t done = 0;
  while (done < bytes.size()) {
    const ssize_t n = ::write(fd, bytes.data() + done, bytes.size() - done);
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) throw InputError(path + ": write failed (" + reason(n < 0 ? errno : ENOSPC) + ")");
    done += size_t(n);
  }
}
}  // namespace

int create_exclusive(const std::string& path) {
  const int fd = ::open(path.c_str(), O_WRONLY | O_CREAT | O_EXCL | O_NOFOLLOW | O_CLOEXEC, 0666);
  if (fd < 0) throw InputError(path + ": cannot create file (" + reason(errno) + ")");
  return fd;
}

void write_file_atomically(const std::string& path, const std::function<void(std::ostream&)>& fill) {
  std::ostringstream text;
  fill(text);
  if (!text) throw InputError(path + ": could not format the file");
  const std::string bytes = text.str();
  // Up to a few attempts in case a random name is taken (practically never).
  std::string tmp;
  int fd = -1;
  for (int attempt = 0; fd < 0; ++attempt) {
    tmp = temporary_name(path);
    fd = ::open(tmp.c_str(), O_WRONLY | O_CREAT | O_EXCL | O_NOFOLLOW | O_CLOEXEC, 0666);
    if (fd < 0 && (errno != EEXIST || attempt == 8)) throw InputError(path + ": cannot open for writing (" + reason(errno) + ")");
  }
  try {
    write_all(fd, path, bytes);
    if (::close(fd) != 0) {
      fd = -1;
      throw InputError(path + ": write failed (" + reason(errno) + ")");
    }
    fd = -1;
    if (::rename(tmp.c_str(), path.c_str()) != 0) throw InputError(path + ": cannot write file (" + reason(errno) + ")");
  } catch (...) {
    if (fd >= 0) ::close(fd);
    ::unlink(tmp.c_str());
    throw;
  }
}

void write_path_atomically(const std::string& path, const std::function<void(const std::string&)>& write) {
  const fs::path p(path);
  std::string pattern = (p.parent_path() / ".flankcam-XXXXXX").string();
  if (::mkdtemp(pattern.data()) == nullptr) throw InputError(path + ": cannot create a temporary folder (" + reason(errno) + ")");
  const std::string tmp = (fs::path(pattern) / p.filename()).string();
  try {
    write(tmp);
    if (::rename(tmp.c_str(), path.c_str()) != 0) throw InputError(path + ": cannot write file (" + reason(errno) + ")");
  } catch (...) {
    std::error_code ignored;
    fs::remove_all(pattern, ignored);
    throw;
  }
  std::error_code ignored;
  fs::remove_all(pattern, ignored);
}

}  // namespace flankcam
