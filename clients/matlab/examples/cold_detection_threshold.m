function thresholds = cold_detection_threshold(url, varargin)
% cold_detection_threshold  The DFNS cold detection threshold (CDT) by the method of limits, Psychtoolbox style.
%
% Each run holds the 32 degC baseline, then cools at 1 degC/s until the participant presses a key (a program
% with an until-response ramp: the press stops the ramp on the daemon's next loop tick), returns at 1 degC/s and
% rests. The threshold of a run is the plate temperature at the press (the reply's sensor_c) minus the baseline;
% the CDT is their mean. With Psychtoolbox the press is any key (KbCheck, polled; the daemon's status is asked
% once a second meanwhile, which also renews the HTTP lease); without it, Enter at the prompt (input()).
%
%   thresholds = cold_detection_threshold();                         % http://127.0.0.1:8765, channel 0, 3 runs
%   thresholds = cold_detection_threshold(url, 'Runs', 4, 'Channel', 1, 'Token', T);
%
% Options: 'Channel' (default 0), 'Runs' (default 3), 'BaselineC' (32 degC), 'RateCs' (1 degC/s), 'RestS' (the
% rest after each run, 10 s), 'Token' (default THERMODE_TOKEN), 'SimulatedPressS' (no participant: the press
% comes this many seconds into the ramp; for a demonstration or a test; default none).
% The display stops at its range (15 degC for `thermode serve`, reported as cutoff_c): a run that reaches it
% without a press is reported as no detection (NaN).

if nargin < 1 || isempty(url)
  url = 'http://127.0.0.1:8765';
end
o = struct('Channel', 0, 'Runs', 3, 'BaselineC', 32, 'RateCs', 1, 'RestS', 10, ...
           'Token', getenv('THERMODE_TOKEN'), 'SimulatedPressS', []);
for k = 1:2:numel(varargin)
  o.(varargin{k}) = varargin{k + 1};
end
here = fileparts(mfilename('fullpath'));
addpath(fileparts(here));                         % ThermodeClient.m is one folder up
thermode = ThermodeClient(url, 'Token', o.Token);
have_ptb = isempty(o.SimulatedPressS) && exist('KbCheck', 'file') > 0;
thresholds = nan(1, o.Runs);
for run = 1:o.Runs
  thermode.marker(sprintf('CDT run %d start', run), o.Channel);
  started = thermode.program(o.Channel, {ThermodeClient.step(o.BaselineC), ...
                                        ThermodeClient.ramp(0, o.RateCs, true), ...   % down until the press
                                        ThermodeClient.ramp(o.BaselineC, o.RateCs)});
  if ~isempty(started.cutoff_c)
    fprintf('run %d: the display stops at %.1f degC\n', run, started.cutoff_c);
  end
  pressed = wait_for_press(thermode, o, have_ptb);
  if pressed
    reply = thermode.response(o.Channel);
    if isempty(reply.ended_segment)
      fprintf('run %d: the press came after the ramp ended: no detection\n', run);
    else
      thresholds(run) = reply.sensor_c - o.BaselineC;
      fprintf('run %d: pressed at %.2f degC (%.2f degC below the baseline)\n', run, reply.sensor_c, ...
              -thresholds(run));
    end
  else
    fprintf('run %d: no press before the cut-off\n', run);
  end
  thermode.wait_for_program_end(o.Channel, 120);
  pause(o.RestS);
end
thermode.release(o.Channel);
fprintf('CDT %.2f degC (mean of %d runs)\n', mean(thresholds(~isnan(thresholds))), sum(~isnan(thresholds)));
end

function pressed = wait_for_press(thermode, o, have_ptb)
% Waits for the participant's key (or the simulated press); false when the ramp ran out first.
ramp_s = (o.BaselineC - 15) / o.RateCs + 2;      % to the display's lowest set-point, with a margin
if ~isempty(o.SimulatedPressS)
  pause(o.SimulatedPressS);
  pressed = true;
elseif have_ptb
  pressed = false;
  started = tic;
  polled = 0;
  while ~pressed && toc(started) < ramp_s
    pressed = KbCheck();                           % any key
    if toc(started) - polled >= 1                  % once a second: still ramping? (renews the lease too)
      polled = toc(started);
      s = thermode.status();
      if ~isequal(s.channels(o.Channel + 1).program_segment, 1)
        return;
      end
    end
    WaitSecs(0.002);
  end
else
  input('Press Enter as soon as you feel cold... ', 's');
  pressed = true;
end
end
