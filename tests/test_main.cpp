// doctest's main, plus one rule doctest lacks: a run in which no test case matches the filters
// fails. CTest runs each discovered test as `suite --test-case=NAME`; a name doctest_discover_tests
// mangled (split at ';') matches nothing and must not pass silently.
#define DOCTEST_CONFIG_IMPLEMENT
#include <doctest/doctest.h>

#include <cstdio>

namespace {

struct RunCount {
  unsigned matched = 0;
  bool ended = false;
};
RunCount& run_count() {
  static RunCount c;
  return c;
}

struct ZeroMatchListener : doctest::IReporter {
  explicit ZeroMatchListener(const doctest::ContextOptions&) {}
  void report_query(const doctest::QueryData&) override {}
  void test_run_start() override {}
  void test_run_end(const doctest::TestRunStats& s) override {
    run_count().matched = s.numTestCasesPassingFilters;
    run_count().ended = true;
  }
  void test_case_start(const doctest::TestCaseData&) override {}
  void test_case_reenter(const doctest::TestCaseData&) override {}
  void test_case_end(const doctest::CurrentTestCaseStats&) override {}
  void test_case_exception(const doctest::TestCaseException&) override {}
  void subcase_start(const doctest::SubcaseSignature&) override {}
  void subcase_end() override {}
  void log_assert(const doctest::AssertData&) override {}
  void log_message(const doctest::MessageData&) override {}
  void test_case_skipped(const doctest::TestCaseData&) override {}
};
REGISTER_LISTENER("zero_match", 1, ZeroMatchListener);

}  // namespace

int main(int argc, char** argv) {
  doctest::Context context(argc, argv);
  const int result = context.run();
  if (context.shouldExit()) return result;  // --list-test-cases, --help, ...
  if (run_count().ended && run_count().matched == 0) {
    std::fprintf(stderr, "no test case matches the filters (a test name containing ';' is split by CTest)\n");
    return result != 0 ? result : 1;
  }
  return result;
}
