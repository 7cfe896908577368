#include "pipeline/output_dir.h"

#include <fmt/format.h>
#include <limits.h>
#include <pthread.h>
#include <signal.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstring>
#include <map>
#include <mutex>
#include <thread>

#include "core/errors.h"

namespace flankcam::pipeline {
namespace fs = std::filesystem;

void check_file_name(const std::string& name, const std::string& what) {
  if (name.empty()) throw InputError(what + ": empty file name");
  if (name.size() > NAME_MAX) throw InputError(fmt::format("{}: file name of {} bytes, the limit is {}", what, name.size(), NAME_MAX));
  if (name.front() == '.') throw InputError(what + ": '" + name + "' starts with '.' (hidden, or a path outside the output folder)");
  for (const char c : name) {
    if (c == '/') throw InputError(what + ": '" + name + "' contains '/' (must be a plain file name inside the output folder)");
    if (static_cast<unsigned char>(c) < 0x20 || c == 0x7f) throw InputError(what + ": the file name contains a control character");
  }
}

void OutputPlan::add(const std::string& name, const std::string& owner) {
  check_file_name(name, owner);
  for (const auto& [n, o] : files_)
    if (n == name)
      throw InputError(fmt::format("output name clash: {} would be written for {} and for {} (rename one of them)", name, o, owner));
  files_.emplace_back(name, owner);
}

namespace {
std::string why(int err) { return std::strerror(err); }

[[noreturn]] void refuse(const fs::path& target, const std::string& what) {
  throw InputError(fmt::format("--out {}: {}", target.string(), what));
}

// Output folders not yet committed: what an interrupt (Ctrl-C, SIGTERM, SIGHUP) removes before the
// process ends, so that a run stopped by its user leaves nothing behind either. The signals are
// blocked in the thread that makes the first OutputDir (the main thread, before any worker
// thread exists, so every later thread inherits the mask) and taken by one thread waiting for them.
struct Unfinished {
  fs::path staging;
  std::vector<fs::path> created;
};
struct Registry {
  std::mutex mutex;
  std::map<const void*, Unfinished> live;
};
Registry& registry() {
  static Registry* r = new Registry;  // never destroyed: the waiting thread may use it at exit
  return *r;
}

// The parent folders a run made, newest first (each empty by then, or left as it is).
void remove_created(const std::vector<fs::path>& created) {
  for (auto it = created.rbegin(); it != created.rend(); ++it) ::rmdir(it->c_str());
}

void remove_unfinished(const Unfinished& u) {
  std::error_code ignored;
  fs::remove_all(u.staging, ignored);
  remove_created(u.created);
}

void watch_interrupts() {
  static std::once_flag once;
  std::call_once(once, [] {
    sigset_t set;
    sigemptyset(&set);
    for (int s : {SIGINT, SIGTERM, SIGHUP}) sigaddset(&set, s);
    if (pthread_sigmask(SIG_BLOCK, &set, nullptr) != 0) return;
    std::thread([set] {
      int sig = 0;
      if (sigwait(&set, &sig) != 0) return;
      {
        std::lock_guard<std::mutex> lock(registry().mutex);
        for (const auto& [who, u] : registry().live) remove_unfinished(u);
      }
      const std::string line = fmt::format("flankcam: interrupted ({}); nothing written to the output folder\n",
                                           sig == SIGINT ? "SIGINT" : sig == SIGTERM ? "SIGTERM" : "SIGHUP");
      (void)!::write(STDERR_FILENO, line.data(), line.size());
      ::_exit(128 + sig);
    }).detach();
  });
}
}  // namespace

OutputDir::OutputDir(const fs::path& target) : target_(target) {
  const std::string text = target.string();
  if (text.empty()) throw InputError("--out: empty path");
  // Messages quote at most the start of an over-long path.
  const fs::path shown = text.size() > 80 ? fs::path(text.substr(0, 60) + "...") : target;
  if (text.size() >= PATH_MAX) refuse(shown, fmt::format("the path is {} characters long, the limit is {}", text.size(), PATH_MAX - 1));
  for (const fs::path& part : target)
    if (part.string().size() > NAME_MAX)
      refuse(shown, fmt::format("a folder name is {} characters long, the limit is {}", part.string().size(), NAME_MAX));
  std::error_code ec;
  const fs::path resolved = fs::weakly_canonical(fs::absolute(target), ec);
  if (ec) refuse(shown, "cannot resolve the path (" + ec.message() + ")");
  for (const char* special : {"/proc", "/sys", "/dev"}) {
    const fs::path root(special);
    const auto mismatch = std::mismatch(root.begin(), root.end(), resolved.begin(), resolved.end());
    if (mismatch.first == root.end()) refuse(shown, fmt::format("is under {}, a system folder, not a place for output files", special));
  }
  const fs::file_status st = fs::status(target, ec);
  if (fs::exists(st) && !fs::is_directory(st)) refuse(shown, "exists and is not a folder");

  // From here on, an interrupt removes what this object creates (not before it is registered).
  watch_interrupts();
  std::lock_guard<std::mutex> lock(registry().mutex);
  fs::path parent;
  std::string pattern;
  if (fs::is_directory(st)) {
    into_existing_ = true;
    pattern = (target / ".flankcam-XXXXXX").string();
  } else {
    // Create the missing parents (remembered, removed again on failure), then the private folder beside the target.
    parent = resolved.parent_path();
    std::vector<fs::path> missing;
    for (fs::path p = parent; !p.empty() && !fs::exists(p, ec); p = p.parent_path()) {
      missing.insert(missing.begin(), p);
      if (p == p.root_path()) break;
    }
    for (const fs::path& p : missing) {
      if (::mkdir(p.c_str(), 0777) != 0) {
        const int err = errno;
        remove_created(created_);
        created_.clear();
        refuse(shown, fmt::format("cannot create the folder {} ({})", p.string(), why(err)));
      }
      created_.push_back(p);
    }
    if (!fs::is_directory(parent, ec)) {
      remove_created(created_);
      created_.clear();
      refuse(shown, parent.string() + " is not a folder");
    }
    pattern = (parent / ("." + resolved.filename().string() + ".flankcam-XXXXXX")).string();
  }
  if (::mkdtemp(pattern.data()) == nullptr) {
    const int err = errno;
    remove_created(created_);
    created_.clear();
    refuse(shown, "cannot write there (" + why(err) + ")");
  }
  staging_ = pattern;
  if (!into_existing_) target_ = resolved;
  registry().live[this] = {staging_, created_};
}

OutputDir::~OutputDir() {
  std::lock_guard<std::mutex> lock(registry().mutex);
  registry().live.erase(this);
  if (!committed_) remove_unfinished({staging_, created_});
}

std::string OutputDir::file(const std::string& name) {
  check_file_name(name, "output file");
  if (!used_.insert(name).second)
    throw InputError(fmt::format("output name clash: {} would be written twice in {} (two patches or inputs give it the "
                                 "same name)",
                                 name, target_.string()));
  names_.push_back(name);
  return (staging_ / name).string();
}

void OutputDir::commit() {
  if (committed_) return;
  // An interrupt during the move waits for it: the output is then whole.
  std::lock_guard<std::mutex> lock(registry().mutex);
  if (!into_existing_) {
    // mkdtemp made the folder 0700; a finished output folder gets the usual 0777 minus the umask.
    const mode_t mask = ::umask(0);
    ::umask(mask);
    ::chmod(staging_.c_str(), 0777 & ~mask);
    if (::rename(staging_.c_str(), target_.c_str()) == 0) {
      committed_ = true;
      registry().live.erase(this);
      return;
    }
    const int err = errno;
    std::error_code ec;
    if (!fs::is_directory(target_, ec)) refuse(target_, "cannot move the finished output into place (" + why(err) + ")");
    // The target appeared meanwhile: move the files into it as below.
  }
  for (const std::string& name : names_) {
    const fs::path from = staging_ / name, to = target_ / name;
    std::error_code ec;
    if (!fs::exists(fs::symlink_status(from, ec))) continue;  // a writer that chose not to write it
    if (::rename(from.c_str(), to.c_str()) != 0) refuse(target_, fmt::format("cannot move {} into place ({})", name, why(errno)));
  }
  std::error_code ignored;
  fs::remove_all(staging_, ignored);
  committed_ = true;
  registry().live.erase(this);
}

}  // namespace flankcam::pipeline
