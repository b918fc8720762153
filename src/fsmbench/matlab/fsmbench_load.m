function [G, K, Kd, info] = fsmbench_load(outdir, varargin)
%FSMBENCH_LOAD  fsmbench's plant and controllers as ss objects (MATLAB or Octave).
%
%   [G, K] = fsmbench_load(OUTDIR)
%   [G, K, Kd, info] = fsmbench_load(OUTDIR, 'PlantDir', DIR, 'PadeOrder', N)
%
%   Reads OUTDIR/plant.mat (written by "fsmbench identify" and "fsmbench study")
%   and OUTDIR/controllers.mat (written by "fsmbench design" and "fsmbench study")
%   and returns
%
%     G     struct of continuous ss models with signal names:
%           G.sys  the whole bench, inputs Uch, Ucv, Unh, Unv [V], outputs
%                  Vch, Vcv, Ich, Icv [V], Rh, Rv [rad], Vph, Vpv [V], with its
%                  input delays (see Delays below);
%           G.Gi, G.Zc, G.Ga, G.Gc, G.Gn, G.Gd  its blocks (no delays).
%           [] when there is no plant.mat (a note says so).
%     K     struct of continuous controllers: K.seed_controller,
%           K.fsmbench_controller (both Rh, Rv [rad] -> Uch, Ucv [V]),
%           K.newport_controller (Rh, Rv -> Unh, Unv [V]) and K.iff_controller
%           (Vch, Vcv -> Uch, Ucv); [] when there is no controllers.mat.
%     Kd    the same controllers, discrete (sample time Kd.(name).Ts [s]);
%           info.discretisation says how they were discretised (by default
%           Tustin prewarped at each notch, so notches stay in place).
%     info  struct: plant_source (plant.mat), design_plant_source (the plant
%           the controllers were designed on), qd_gain_v_per_rad (4QD gain
%           Gd, fields h and v, [V/rad]: R = Vp / Gd), discretisation, Ts [s],
%           feedback ('u = -K y'), InputDelay [s] of G.sys, pade_order and
%           notes (cell array of the notes printed).
%
%   Feedback: every feedback controller is closed as u = -K y, e.g. in MATLAB
%     L = G.sys({'Rh','Rv'}, {'Uch','Ucv'}) * K.fsmbench_controller;
%     S = feedback(eye(2), L);               % sensitivity
%   (the IFF controller of seed 8.2 is added to the command: u = +Kppf y).
%
%   Delays: in MATLAB, G.sys.InputDelay holds the plant's input delays [s]
%   exactly. Octave's control package has no InputDelay: there each delay
%   is replaced by a Pade approximation of order N (option 'PadeOrder',
%   default 6: for the bench's 0.5 ms Newport delay the error of exp(-s*tau)
%   is 4e-7 at 1 kHz and 2e-3 at 2 kHz), placed in series at the input,
%   and a note is printed;
%   'PadeOrder', 0 leaves the delays out of G.sys (they stay in
%   info.InputDelay). The exact delays are always in info.InputDelay.
%
%   Options (name, value pairs):
%     'PlantDir'   folder holding plant.mat when it is not OUTDIR.
%     'PadeOrder'  Pade order used for the delays in Octave (default 6).
%
%   Example:
%     [G, K, Kd] = fsmbench_load('out');
%     bode(K.seed_controller(1, 1), Kd.seed_controller(1, 1))
%
%   Written by fsmbench next to its outputs; the same controllers as
%   second-order sections for a real-time target are in controllers_sos.json.

  if nargin < 1
    outdir = '.';
  end
  opts = struct('PlantDir', outdir, 'PadeOrder', 6);
  if mod(numel(varargin), 2) ~= 0
    error('fsmbench_load: options come as name, value pairs');
  end
  for i = 1:2:numel(varargin)
    name = varargin{i};
    if ~ischar(name) || ~isfield(opts, name)
      error('fsmbench_load: unknown option %s (use PlantDir or PadeOrder)', ...
            char(string_of(name)));
    end
    opts.(name) = varargin{i + 1};
  end

  octave = exist('OCTAVE_VERSION', 'builtin') ~= 0;
  if octave
    pkg('load', 'control');
  end

  info = struct('plant_source', '', 'design_plant_source', '', ...
                'qd_gain_v_per_rad', struct(), 'discretisation', '', 'Ts', NaN, ...
                'feedback', 'u = -K y', 'InputDelay', [], 'pade_order', 0, ...
                'notes', {{}});

  % ---------------------------------------------------------------- plant
  G = [];
  plant_file = fullfile(opts.PlantDir, 'plant.mat');
  if exist(plant_file, 'file')
    p = load(plant_file);
    if isfield(p, 'source')
      info.plant_source = char(p.source);
    end
    G = struct();
    blocks = {'Gi', 'Zc', 'Ga', 'Gc', 'Gn', 'Gd'};
    for i = 1:numel(blocks)
      if isfield(p, blocks{i})
        G.(blocks{i}) = make_ss(p.(blocks{i}));
      end
    end
    if ~isfield(p, 'sys')
      error('fsmbench_load: %s has no variable sys (the whole plant)', plant_file);
    end
    delay = zeros(size(p.sys.D, 2), 1);
    if isfield(p.sys, 'InputDelay')
      delay = double(p.sys.InputDelay(:));
    end
    info.InputDelay = delay;
    sys = make_ss(p.sys);
    if any(delay > 0)
      if ~octave
        sys.InputDelay = delay;
      elseif opts.PadeOrder > 0
        sys = with_pade(sys, delay, opts.PadeOrder);
        info.pade_order = opts.PadeOrder;
        info = note(info, sprintf(['Octave has no InputDelay: the input delays of G.sys ' ...
          '(%s s) are Pade approximations of order %d; exact values in info.InputDelay'], ...
          num2str(delay.', '%.6g '), opts.PadeOrder));
      else
        info = note(info, sprintf(['Octave has no InputDelay and PadeOrder is 0: G.sys ' ...
          'has NO input delays (exact values %s s in info.InputDelay)'], ...
          num2str(delay.', '%.6g ')));
      end
    end
    G.sys = sys;
  else
    info = note(info, sprintf('no plant.mat in %s: G is empty', opts.PlantDir));
  end

  % ---------------------------------------------------------------- controllers
  K = [];
  Kd = [];
  ctrl_file = fullfile(outdir, 'controllers.mat');
  if exist(ctrl_file, 'file')
    c = load(ctrl_file);
    names = fieldnames(c);
    if isfield(c, 'fsmbench')
      meta = c.fsmbench;
      names = cellstr(meta.controllers);
      info.Ts = double(meta.Ts);
      info.discretisation = char(meta.discretisation);
      if isfield(meta, 'discretisation_text')
        info.discretisation = [info.discretisation ': ' char(meta.discretisation_text)];
      end
      if isfield(meta, 'qd_gain_v_per_rad')
        info.qd_gain_v_per_rad = meta.qd_gain_v_per_rad;
      end
      if isfield(meta, 'plant_source')
        info.design_plant_source = char(meta.plant_source);
      end
    end
    K = struct();
    Kd = struct();
    for i = 1:numel(names)
      entry = c.(names{i});
      if isstruct(entry) && isfield(entry, 'K') && isfield(entry, 'Kd')
        K.(names{i}) = make_ss(entry.K);
        Kd.(names{i}) = make_ss(entry.Kd);
      end
    end
    if ~isempty(info.plant_source) && ~isempty(info.design_plant_source) ...
        && ~strcmp(info.plant_source, info.design_plant_source)
      info = note(info, sprintf(['the controllers were designed on "%s" but plant.mat ' ...
        'holds "%s"'], info.design_plant_source, info.plant_source));
    end
  else
    info = note(info, sprintf('no controllers.mat in %s: K and Kd are empty', outdir));
  end
end


function sys = make_ss(st)
% One fsmbench struct (A, B, C, D, InputName, OutputName, Ts) as an ss object.
  D = double(st.D);
  [ny, nu] = size(D);
  nx = size(st.A, 1);
  A = reshape(double(st.A), nx, nx);
  B = reshape(double(st.B), nx, nu);
  C = reshape(double(st.C), ny, nx);
  ts = 0;
  if isfield(st, 'Ts')
    ts = double(st.Ts);
  end
  if ts > 0
    sys = ss(A, B, C, D, ts);
  else
    sys = ss(A, B, C, D);
  end
  sys.InputName = names_of(st.InputName);
  sys.OutputName = names_of(st.OutputName);
  if isfield(st, 'StateName') && numel(names_of(st.StateName)) == nx && nx > 0
    sys.StateName = names_of(st.StateName);
  end
end


function c = names_of(x)
% Signal names as a column cell array of char, from a cell or a char matrix.
  if ischar(x)
    c = cellstr(x);
  else
    c = cellfun(@char, x(:), 'UniformOutput', false);
  end
  c = c(:);
end


function sys = with_pade(sys, delay, n)
% sys with a Pade approximation of order n of exp(-s*delay(i)) at each input i.
  in_names = sys.InputName;
  out_names = sys.OutputName;
  nu = numel(delay);
  parts = cell(1, nu);
  for i = 1:nu
    parts{i} = pade_ss(delay(i), n);
  end
  sys = sys * append(parts{:});
  sys.InputName = in_names;
  sys.OutputName = out_names;
end


function p = pade_ss(tau, n)
% (n, n) Pade approximation of exp(-s*tau) as a state-space model. Built in the
% normalised variable x = s*tau (coefficients of order 1) and time-scaled, so
% that a short delay does not give coefficients spanning (1/tau)^n.
  if tau <= 0
    p = ss(1);
    return
  end
  k = 0:n;
  c = factorial(2 * n - k) .* factorial(n) ./ (factorial(2 * n) .* factorial(k) ...
      .* factorial(n - k));
  num = fliplr(c .* (-1) .^ k);   % descending powers of x
  den = fliplr(c);
  [a, b, cc, d] = ssdata(ss(tf(num, den)));
  p = ss(a / tau, b / tau, cc, d);
end


function info = note(info, text)
% Record and print a note.
  info.notes{end + 1} = text;
  fprintf('fsmbench_load: %s\n', text);
end


function s = string_of(x)
  if ischar(x)
    s = x;
  else
    s = class(x);
  end
end
