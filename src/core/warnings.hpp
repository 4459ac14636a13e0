// brume — a run's warnings on stderr, one spelling for every command; within
// a batch frame, named after the frame and kept for its results line.
#pragma once

#include <string>
#include <vector>

namespace brume {

// Prints "brume COMMAND: warning: TEXT" on stderr ("brume: warning: TEXT"
// for an empty command). On a thread inside a FrameWarnings scope the line
// names the frame ("brume COMMAND: frame 'KEY': warning: TEXT") and the text
// is kept for the frame. The record holds the warning too: its caller puts it
// there.
void print_warning(const std::string& command, const std::string& text);

// `brume batch`'s frame on this thread: its warnings name KEY and are kept.
// Scopes do not nest; frames on other threads have their own.
class FrameWarnings {
 public:
  explicit FrameWarnings(std::string key);
  ~FrameWarnings();
  FrameWarnings(const FrameWarnings&) = delete;
  FrameWarnings& operator=(const FrameWarnings&) = delete;
  const std::vector<std::string>& texts() const { return texts_; }

 private:
  friend void print_warning(const std::string&, const std::string&);
  std::string key_;
  std::vector<std::string> texts_;
  FrameWarnings* outer_;
};

}  // namespace brume
