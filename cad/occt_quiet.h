// Private to cad/: silences OCCT's default messenger (readers and writers print statistics to
// stdout) for the life of the object; the printers are put back afterwards.
#pragma once
#include <Message.hxx>
#include <Message_Messenger.hxx>

namespace flankcam::detail {

class QuietOcct {
 public:
  QuietOcct() {
    const Handle(Message_Messenger)& m = Message::DefaultMessenger();
    for (Message_SequenceOfPrinters::Iterator it(m->Printers()); it.More(); it.Next()) saved_.Append(it.Value());
    m->ChangePrinters().Clear();
  }
  ~QuietOcct() {
    const Handle(Message_Messenger)& m = Message::DefaultMessenger();
    for (Message_SequenceOfPrinters::Iterator it(saved_); it.More(); it.Next()) m->AddPrinter(it.Value());
  }
  QuietOcct(const QuietOcct&) = delete;
  QuietOcct& operator=(const QuietOcct&) = delete;

 private:
  Message_SequenceOfPrinters saved_;
};

}  // namespace flankcam::detail
