// The output folder of one command (--out). Nothing appears there until every file is written:
//  - the target is checked first (not a file, not under /proc, /sys or /dev, path within the
//    system's limits, a folder can be created there) so a bad --out is refused before any work;
//  - files go into a fresh private folder (mkdtemp): beside the target when the target does not
//    exist yet (commit() renames it into place), inside the target when it is an existing folder
//    (commit() moves each file in, replacing files of the same name; other files are left alone);
//  - destroyed without commit() (an error anywhere), it removes everything it wrote, including
//    the parent folders it created.
#pragma once
#include <filesystem>
#include <set>
#include <string>
#include <vector>

namespace flankcam::pipeline {

// A file name a command may write: not empty, no '/', no leading '.', no control characters,
// at most 255 bytes. Throws InputError "WHAT: ..." otherwise.
void check_file_name(const std::string& name, const std::string& what);

// Names of the files a command will write, each with what it is for messages. Throws InputError
// naming both owners when two outputs would get the same name (one would silently replace the other).
class OutputPlan {
 public:
  void add(const std::string& name, const std::string& owner);
 private:
  std::vector<std::pair<std::string, std::string>> files_;
};

class OutputDir {
 public:
  // Throws InputError "--out DIR: ..." when the target cannot be an output folder.
  explicit OutputDir(const std::filesystem::path& target);
  ~OutputDir();
  OutputDir(const OutputDir&) = delete;
  OutputDir& operator=(const OutputDir&) = delete;

  // Where to write file `name` now (in the private folder). Throws InputError when the name is
  // not a plain file name or was already used in this run.
  [[nodiscard]] std::string file(const std::string& name);
  // Moves everything into the target. Throws InputError when that fails (nothing is left behind
  // when the target did not exist).
  void commit();

  [[nodiscard]] const std::filesystem::path& target() const { return target_; }
  [[nodiscard]] const std::filesystem::path& staging() const { return staging_; }

 private:
  std::filesystem::path target_, staging_;
  bool into_existing_ = false, committed_ = false;
  std::vector<std::filesystem::path> created_;  // parent folders this object created, outermost first
  std::vector<std::string> names_;              // in the order written
  std::set<std::string> used_;
};

}  // namespace flankcam::pipeline
